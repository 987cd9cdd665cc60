//! The `section!` macro a section's table is written in, and the macros it
//! expands each key's line with (its type when it may be absent, its
//! default, its value read, the check of its target).

/// The resolved type of a key: `Option<T>` for a key that may be absent.
#[macro_export]
#[doc(hidden)]
macro_rules! resolved_ty {
    (absent, $ty:ty) => { Option<$ty> };
    ($other:ident, $ty:ty) => { $ty };
}

/// A key's [`KeyDefault`] from its declaration.
#[macro_export]
#[doc(hidden)]
macro_rules! key_default {
    ($ty:ty, value($e:expr)) => {{
        fn rendered() -> String {
            $crate::decl::render::<$ty>($e)
        }
        $crate::decl::KeyDefault::Value(rendered)
    }};
    ($ty:ty, required($e:expr)) => {{
        fn rendered() -> String {
            $crate::decl::render::<$ty>($e)
        }
        $crate::decl::KeyDefault::Required(rendered)
    }};
    ($ty:ty, absent($meaning:expr, $e:expr)) => {{
        fn rendered() -> String {
            $crate::decl::render::<$ty>($e)
        }
        $crate::decl::KeyDefault::Absent($meaning, rendered)
    }};
}

/// A key's value from what the file gives (`raw`) and its declaration.
#[macro_export]
#[doc(hidden)]
macro_rules! key_value {
    ($ctx:expr, $decl:expr, $raw:expr, $ty:ty, value($e:expr)) => {
        Ok::<$ty, $crate::ConfigError>(match $raw {
            Some(raw) => <$ty as $crate::decl::KeyType>::from_raw(raw),
            None => $crate::decl::IntoKey::<$ty>::into_key($e),
        })
    };
    ($ctx:expr, $decl:expr, $raw:expr, $ty:ty, required($e:expr)) => {
        match $raw {
            Some(raw) => Ok(<$ty as $crate::decl::KeyType>::from_raw(raw)),
            None => Err($crate::decl::missing($ctx, $decl)),
        }
    };
    ($ctx:expr, $decl:expr, $raw:expr, $ty:ty, absent($meaning:expr, $e:expr)) => {
        Ok::<Option<$ty>, $crate::ConfigError>($raw.map(<$ty as $crate::decl::KeyType>::from_raw))
    };
}

/// Makes the compiler check a declared target exists.
#[macro_export]
#[doc(hidden)]
macro_rules! key_target {
    ($t:ident :: $v:ident . $f:ident) => {
        let _ = |t: &$t| matches!(t, $t::$v { $f: _, .. });
    };
    ($t:ident :: $m:ident) => {
        let _ = $t::$m;
    };
    ($t:ident $(. $f:ident)+) => {
        let _ = |t: &$t| {
            let _ = &t $(.$f)+;
        };
    };
    ($t:ident) => {
        let _ = |_: &$t| ();
    };
}

/// Declares a section of the configuration: one line per key,
///
/// ```text
/// /// What the section is, one line.
/// section "name";
/// const WORDS: &str = "a text several keys' ranges share";
/// /// One line: what it is.
/// name: Type = value(default) | required(example) | absent("meaning", example),
///     range => [Domain.field];
/// ```
///
/// and makes the section's serde mirror (`Raw`, unknown keys refused), its
/// read form (`Section`: each key's value or default; `Option` for a key
/// that may be absent), the declarations (`KEY.name`, `KEYS`), the check of
/// every key's range (`Section::check_ranges`) and a compile-time check of
/// every target.
#[macro_export]
macro_rules! section {
    (
        $(#[doc = $sdoc:literal])+
        section $section:literal;
        $(const $cname:ident: &str = $cval:literal;)*
        $(
            $(#[doc = $doc:literal])+
            $key:ident : $ty:ty = $dkind:ident $dargs:tt , $range:expr => [$($target:tt)+];
        )+
    ) => {
        /// The section's name in the file, dotted.
        pub(crate) const SECTION: &str = $section;

        $(const $cname: &str = $cval;)*


        /// The section as the file writes it: every key optional here
        /// (missing required keys are refused by [`Raw::resolve`]), unknown
        /// keys refused.
        #[derive(Debug, Default, serde::Deserialize)]
        #[serde(deny_unknown_fields, default)]
        pub(crate) struct Raw {
            $( $key: Option<<$ty as $crate::decl::KeyType>::Raw>, )+
        }

        /// The section's keys as the file gives them: each key's value, its
        /// default, or (for a key that may be absent) `None`; in a loaded
        /// [`Config`](crate::Config), each within its declared range and
        /// every check passed.
        #[derive(Debug, Clone, PartialEq)]
        pub struct Section {
            $(
                $(#[doc = $doc])+
                pub $key: $crate::resolved_ty!($dkind, $ty),
            )+
        }

        /// The declaration of each key of the section.
        #[derive(Debug, Clone, Copy)]
        pub(crate) struct Keys {
            $( pub(crate) $key: $crate::decl::KeyDecl, )+
        }

        /// The section's keys, by name.
        pub(crate) const KEY: Keys = Keys {
            $(
                $key: $crate::decl::KeyDecl {
                    section: SECTION,
                    name: stringify!($key),
                    key: concat!($section, ".", stringify!($key)),
                    doc: concat!($($doc),+),
                    default: $crate::key_default!($ty, $dkind $dargs),
                    kind: <$ty as $crate::decl::KeyType>::KIND,
                    range: $range,
                    target: stringify!($($target)+),
                },
            )+
        };

        /// The section's keys, in the file's order.
        pub(crate) const KEYS: &[$crate::decl::KeyDecl] = &[$(KEY.$key),+];

        /// The section: its name, its one-line doc and its keys.
        pub(crate) const DECL: $crate::decl::SectionDecl = $crate::decl::SectionDecl {
            name: SECTION,
            doc: concat!($($sdoc),+),
            keys: KEYS,
        };

        impl Raw {
            /// Each key's value or default; a missing required key refused.
            // `ctx`: only a section with a required key makes an error.
            #[allow(unused_variables)]
            pub(crate) fn resolve(
                self,
                ctx: &$crate::toml_file::Ctx<'_>,
            ) -> Result<Section, $crate::ConfigError> {
                Ok(Section {
                    $(
                        $key: $crate::key_value!(
                            ctx, &KEY.$key, self.$key, $ty, $dkind $dargs
                        )?,
                    )+
                })
            }
        }

        impl Section {
            /// Every key's declared range, in the file's order.
            pub(crate) fn check_ranges(
                &self,
                ctx: &$crate::toml_file::Ctx<'_>,
            ) -> Result<(), $crate::ConfigError> {
                $( $crate::decl::check(ctx, &KEY.$key, &self.$key)?; )+
                Ok(())
            }
        }

        /// The compiler checks each declared target exists.
        #[allow(dead_code, clippy::no_effect_underscore_binding)]
        fn targets() {
            $( $crate::key_target!($($target)+); )+
        }
    };
}
