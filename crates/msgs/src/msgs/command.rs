//! The operator's commands, declared once (issue 36): one table
//! ([`commands!`] below) gives each command its wire code
//! ([`command_kind`]), its recorded code ([`CommandKindCode`], or "recorded
//! as another kind", or "answered without the loop, not recorded"), its
//! typed arguments with unit-named fields (and the recorded field of each),
//! its log text and its one-line help. From the table come:
//!
//! - [`Request`], the loop's vocabulary (`sar_loop::step` re-exports it),
//!   and [`DaemonCommand`], the commands answered without the loop;
//! - the wire's encoder ([`Request::to_wire`], [`DaemonCommand::to_wire`])
//!   and decoder ([`decode`]: an unknown kind is a typed error naming it);
//! - the recording's encoder ([`Request::record`]) and decoder
//!   ([`Request::from_recorded`], which maps the layout of recordings older
//!   than issue 36 first, [`CommandLayoutCode::Old`]);
//! - the log text (`Display` of [`Request`]) and the help
//!   ([`Request::help`], [`COMMANDS`]).
//!
//! On the wire a command's arguments are [`CommandMsg::args`], in the order
//! and with the unit-named parts the table gives ([`COMMANDS`]'s
//! [`ArgInfo`]). Nothing here allocates: the shared-memory worker decodes on
//! its path, the recorder encodes on the loop's.
//!
//! A new command is one row here, its handling in the loop's step and its
//! `sarctl` subcommand (and, when the loop steps it, its `COMMAND_*`
//! constant in `msg/CycleInput.msg`, which `tests/layout.rs` demands).

use super::CycleInput as CycleInputMsg;
use crate::cdr::{CdrError, CdrField, CdrReader, CdrWriter, FixedLayout};
use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use sar_estimator::Vec3;
use sar_estimator::guard::ForceLimits;

/// Argument slots of [`CommandMsg::args`] (the most a command takes: an
/// excitation's eight).
pub const COMMAND_ARGS: usize = 8;

/// The version of [`CommandMsg`]'s layout, in its iceoryx2 type name
/// ([`COMMAND_MSG_TYPE_NAME`]): a `sarctl` of another version opening a
/// `sard`'s command service is told "different builds"
/// (`sar_shm`'s open error), never misread. 2: issue 36 (the arguments as
/// the command table's unit-named slots, `args`); 1 (the type's Rust
/// path): `tip_m` and `limits_n`.
pub const COMMAND_MSG_VERSION: u32 = 2;

/// [`CommandMsg`]'s iceoryx2 type name: its path and
/// [`COMMAND_MSG_VERSION`] (a test checks both).
pub const COMMAND_MSG_TYPE_NAME: &str = "sar_msgs::wire::CommandMsg@2";

/// An operator command: a row of the command table (`crate::command`),
/// encoded by `Request::to_wire` or `DaemonCommand::to_wire` and decoded
/// by `command::decode`.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[type_name("sar_msgs::wire::CommandMsg@2")]
#[repr(C)]
pub struct CommandMsg {
    /// [`command_kind`].
    pub kind: u32,
    /// Padding, 0.
    pub reserved: u32,
    /// The caller's id, echoed.
    pub id: u64,
    /// The command's arguments in the table's order, each slot named with
    /// its unit there (`command::COMMANDS`, `ArgInfo::parts`); unused
    /// slots 0.
    pub args: [f64; COMMAND_ARGS],
}

/// Whether a command of `slots` numbers fits [`CommandMsg::args`].
const fn fits(slots: usize) -> bool {
    slots <= COMMAND_ARGS
}

/// An excitation as requested (the dynamic identification's, issue 26,
/// `sar_loop::excite`): per axis (q1, q2, q3) an amplitude and a
/// frequency, its duration and its fades.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExciteRequest {
    /// Each axis's amplitude, m (>= 0).
    pub amplitude_m: [f64; 3],
    /// Each axis's frequency, Hz (> 0).
    pub freq_hz: [f64; 3],
    /// The whole duration with the fades, s.
    pub duration_s: f64,
    /// The fade in and the fade out, s each (> 0, at most half the
    /// duration).
    pub fade_s: f64,
}

sar_snapshot::snap_struct!(ExciteRequest {
    amplitude_m,
    freq_hz,
    duration_s,
    fade_s,
});

/// Why a command could not be decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum CommandError {
    /// The wire's kind is no command of this build.
    #[error("unknown command kind {kind}")]
    UnknownKind {
        /// The kind received.
        kind: u32,
    },
}

/// Writes a command's arguments into [`CommandMsg::args`], in order.
#[derive(Debug)]
pub struct ArgWriter {
    args: [f64; COMMAND_ARGS],
    at: usize,
}

impl ArgWriter {
    fn new() -> Self {
        Self {
            args: [0.0; COMMAND_ARGS],
            at: 0,
        }
    }
    /// Puts one number (a compile-time check keeps every command within
    /// [`COMMAND_ARGS`]).
    pub fn put(&mut self, v: f64) {
        if let Some(slot) = self.args.get_mut(self.at) {
            *slot = v;
        }
        self.at += 1;
    }
}

/// Reads a command's arguments from [`CommandMsg::args`], in order.
#[derive(Debug)]
pub struct ArgReader<'a> {
    args: &'a [f64; COMMAND_ARGS],
    at: usize,
}

impl ArgReader<'_> {
    /// Takes one number (NaN beyond the slots, which a compile-time check
    /// rules out).
    pub fn take(&mut self) -> f64 {
        let v = self.args.get(self.at).copied().unwrap_or(f64::NAN);
        self.at += 1;
        v
    }
    fn take3(&mut self) -> [f64; 3] {
        [self.take(), self.take(), self.take()]
    }
}

/// A command argument's type: its numbers on the wire and the unit-named
/// names of its parts.
pub trait WireArg: Sized {
    /// Slots of [`CommandMsg::args`] it takes.
    const SLOTS: usize;
    /// The names of its parts, each with its unit (empty: one value whose
    /// table name says its unit).
    const PARTS: &'static [&'static str];
    /// Writes it.
    fn put(&self, w: &mut ArgWriter);
    /// Reads it.
    fn take(r: &mut ArgReader<'_>) -> Self;
}

impl WireArg for f64 {
    const SLOTS: usize = 1;
    const PARTS: &'static [&'static str] = &[];
    fn put(&self, w: &mut ArgWriter) {
        w.put(*self);
    }
    fn take(r: &mut ArgReader<'_>) -> Self {
        r.take()
    }
}

impl WireArg for Vec3 {
    const SLOTS: usize = 3;
    const PARTS: &'static [&'static str] = &[];
    fn put(&self, w: &mut ArgWriter) {
        [self.x, self.y, self.z].iter().for_each(|v| w.put(*v));
    }
    fn take(r: &mut ArgReader<'_>) -> Self {
        let [x, y, z] = r.take3();
        Vec3::new(x, y, z)
    }
}

impl WireArg for ForceLimits {
    const SLOTS: usize = 6;
    const PARTS: &'static [&'static str] = &ForceLimits::NAMES;
    fn put(&self, w: &mut ArgWriter) {
        self.to_array().iter().for_each(|v| w.put(*v));
    }
    fn take(r: &mut ArgReader<'_>) -> Self {
        let [a, b, c] = r.take3();
        let [d, e, f] = r.take3();
        ForceLimits::from_array([a, b, c, d, e, f])
    }
}

impl WireArg for ExciteRequest {
    const SLOTS: usize = 8;
    const PARTS: &'static [&'static str] = &["amplitude_m", "freq_hz", "duration_s", "fade_s"];
    fn put(&self, w: &mut ArgWriter) {
        let Self {
            amplitude_m,
            freq_hz,
            duration_s,
            fade_s,
        } = *self;
        amplitude_m.iter().chain(&freq_hz).for_each(|v| w.put(*v));
        w.put(duration_s);
        w.put(fade_s);
    }
    fn take(r: &mut ArgReader<'_>) -> Self {
        Self {
            amplitude_m: r.take3(),
            freq_hz: r.take3(),
            duration_s: r.take(),
            fade_s: r.take(),
        }
    }
}

/// A command argument's recorded fields (`F`: the field, or a tuple of
/// them, of `CycleInput.msg`).
pub trait Recorded<F>: Sized {
    /// Its recorded fields.
    fn to_field(&self) -> F;
    /// It from its recorded fields.
    fn from_field(f: F) -> Self;
}

impl Recorded<f64> for f64 {
    fn to_field(&self) -> f64 {
        *self
    }
    fn from_field(f: f64) -> Self {
        f
    }
}

impl Recorded<[f64; 3]> for Vec3 {
    fn to_field(&self) -> [f64; 3] {
        [self.x, self.y, self.z]
    }
    fn from_field([x, y, z]: [f64; 3]) -> Self {
        Vec3::new(x, y, z)
    }
}

impl Recorded<[f64; 6]> for ForceLimits {
    fn to_field(&self) -> [f64; 6] {
        self.to_array()
    }
    fn from_field(f: [f64; 6]) -> Self {
        ForceLimits::from_array(f)
    }
}

impl Recorded<([f64; 3], [f64; 3], f64, f64)> for ExciteRequest {
    fn to_field(&self) -> ([f64; 3], [f64; 3], f64, f64) {
        (self.amplitude_m, self.freq_hz, self.duration_s, self.fade_s)
    }
    fn from_field(
        (amplitude_m, freq_hz, duration_s, fade_s): ([f64; 3], [f64; 3], f64, f64),
    ) -> Self {
        Self {
            amplitude_m,
            freq_hz,
            duration_s,
            fade_s,
        }
    }
}

/// How a command is recorded (`command_kind` of `CycleInput.msg`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RecordedAs {
    /// As itself: its own code.
    Own(CommandKindCode),
    /// As another kind, told apart by a field that is not 0 (a guarded
    /// move: `MOVE_TIP` with `move_max_force_n`).
    Shared(CommandKindCode, &'static str),
    /// Not recorded: answered without the loop.
    NotRecorded,
}

/// One argument of a command as the table declares it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ArgInfo {
    /// Its name (with its unit, or its parts with theirs).
    pub name: &'static str,
    /// Its parts' names with their units ([`WireArg::PARTS`]).
    pub parts: &'static [&'static str],
    /// Its slots on the wire.
    pub slots: usize,
    /// Its recorded fields of `CycleInput.msg`.
    pub recorded: &'static [&'static str],
}

/// One row of the table, as data (for tests and documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CommandInfo {
    /// Its name ([`Request`] or [`DaemonCommand`] variant).
    pub name: &'static str,
    /// Its wire code ([`command_kind`]).
    pub wire: u32,
    /// How it is recorded.
    pub recorded: RecordedAs,
    /// Its arguments in wire order.
    pub args: &'static [ArgInfo],
    /// Its one-line help.
    pub help: &'static str,
}

/// A command as the wire carries it: a loop request, or one the daemon
/// answers itself.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum WireCommand {
    /// Stepped by the loop.
    Loop(Request),
    /// Answered without the loop.
    Daemon(DaemonCommand),
}

impl From<Request> for WireCommand {
    fn from(r: Request) -> Self {
        Self::Loop(r)
    }
}

impl From<DaemonCommand> for WireCommand {
    fn from(d: DaemonCommand) -> Self {
        Self::Daemon(d)
    }
}

impl WireCommand {
    /// It on the wire, with the caller's `id`.
    pub fn to_wire(&self, id: u64) -> CommandMsg {
        match self {
            Self::Loop(r) => r.to_wire(id),
            Self::Daemon(d) => d.to_wire(id),
        }
    }
}

/// A vector as the log prints it: `[x y z]`, 4 decimals.
struct V3(Vec3);

impl core::fmt::Display for V3 {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "[{:.4} {:.4} {:.4}]", self.0.x, self.0.y, self.0.z)
    }
}

// ---- the table's machinery (one helper per generated piece) ----

/// The `Request` enum from the rows (a variant cannot be a macro call,
/// hence the accumulator).
macro_rules! request_enum {
    ([$($done:tt)*]) => {
        /// An operator request, applied in the cycle whose input carries it
        /// (the loop's vocabulary; the table of [`crate::command`]).
        #[derive(Debug, Clone, Copy, PartialEq)]
        pub enum Request { $($done)* }
    };
    ([$($done:tt)*] [$(#[$m:meta])*] $v:ident {} $($rest:tt)*) => {
        request_enum!([$($done)* $(#[$m])* $v,] $($rest)*);
    };
    ([$($done:tt)*] [$(#[$m:meta])*] $v:ident {
        $( $(#[$fm:meta])* $f:ident: $t:ty => $r:tt ),+ $(,)?
    } $($rest:tt)*) => {
        request_enum!([$($done)* $(#[$m])* $v { $( $(#[$fm])* $f: $t, )+ },] $($rest)*);
    };
    ([$($done:tt)*] [$(#[$m:meta])*] $v:ident (
        $(#[$fm:meta])* $f:ident: $t:ty => $r:tt
    ) $($rest:tt)*) => {
        request_enum!([$($done)* $(#[$m])* $v($t),] $($rest)*);
    };
}

/// `CommandKindCode` from the rows recorded as themselves.
macro_rules! kind_code_enum {
    ([$($done:tt)*] [$($legacy:tt)*]) => {
        code_enum!(
            /// The operator command applied in a cycle (`COMMAND_*` of
            /// `CycleInput.msg`): the table's recorded codes
            /// ([`crate::command`]).
            CommandKindCode, "command_kind" {
                /// None.
                None = 0,
                $($done)*
                $($legacy)*
            }
        );
    };
    ([$($done:tt)*] [$($legacy:tt)*] [$(#[$m:meta])*] (as $($x:tt)*) $($rest:tt)*) => {
        kind_code_enum!([$($done)*] [$($legacy)*] $($rest)*);
    };
    ([$($done:tt)*] [$($legacy:tt)*] [$(#[$m:meta])*] ($k:ident = $c:literal $($x:tt)*) $($rest:tt)*) => {
        kind_code_enum!([$($done)* $(#[$m])* $k = $c,] [$($legacy)*] $($rest)*);
    };
}

/// A row's pattern, binding its arguments by their table names.
macro_rules! req_pat {
    ($v:ident {}) => { Request::$v };
    ($v:ident { $( $(#[$fm:meta])* $f:ident: $t:ty => $r:tt ),+ $(,)? }) => {
        Request::$v { $($f),+ }
    };
    ($v:ident ( $(#[$fm:meta])* $f:ident: $t:ty => $r:tt )) => { Request::$v($f) };
}

/// A row's pattern, its arguments ignored.
macro_rules! req_any {
    ($v:ident {}) => {
        Request::$v
    };
    ($v:ident { $($x:tt)* }) => {
        Request::$v { .. }
    };
    ($v:ident ( $($x:tt)* )) => {
        Request::$v(_)
    };
}

/// A row's arguments' names, as bound by `req_pat!`, and their `ArgInfo`.
macro_rules! req_args {
    ($v:ident {}) => { &[] };
    ($v:ident { $( $(#[$fm:meta])* $f:ident: $t:ty => ($($rf:ident),+) ),+ $(,)? }) => {
        &[$( ArgInfo {
            name: stringify!($f),
            parts: <$t as WireArg>::PARTS,
            slots: <$t as WireArg>::SLOTS,
            recorded: &[$(stringify!($rf)),+],
        } ),+]
    };
    ($v:ident ( $(#[$fm:meta])* $f:ident: $t:ty => ($($rf:ident),+) )) => {
        &[ArgInfo {
            name: stringify!($f),
            parts: <$t as WireArg>::PARTS,
            slots: <$t as WireArg>::SLOTS,
            recorded: &[$(stringify!($rf)),+],
        }]
    };
}

/// A row's slots on the wire.
macro_rules! req_slots {
    ($v:ident {}) => { 0 };
    ($v:ident { $( $(#[$fm:meta])* $f:ident: $t:ty => $r:tt ),+ $(,)? }) => {
        0 $( + <$t as WireArg>::SLOTS )+
    };
    ($v:ident ( $(#[$fm:meta])* $f:ident: $t:ty => $r:tt )) => { <$t as WireArg>::SLOTS };
}

/// Writes a row's bound arguments to the wire.
macro_rules! req_put {
    ($w:ident, $v:ident {}) => {};
    ($w:ident, $v:ident { $( $(#[$fm:meta])* $f:ident: $t:ty => $r:tt ),+ $(,)? }) => {
        $( WireArg::put(&$f, &mut $w); )+
    };
    ($w:ident, $v:ident ( $(#[$fm:meta])* $f:ident: $t:ty => $r:tt )) => {
        WireArg::put(&$f, &mut $w);
    };
}

/// A row's request from the wire's arguments.
macro_rules! req_take {
    ($rd:ident, $v:ident {}) => { Request::$v };
    ($rd:ident, $v:ident { $( $(#[$fm:meta])* $f:ident: $t:ty => $r:tt ),+ $(,)? }) => {
        Request::$v { $( $f: <$t as WireArg>::take(&mut $rd), )+ }
    };
    ($rd:ident, $v:ident ( $(#[$fm:meta])* $f:ident: $t:ty => $r:tt )) => {
        Request::$v(<$t as WireArg>::take(&mut $rd))
    };
}

/// Writes a row's bound arguments to their recorded fields.
macro_rules! req_record {
    ($m:ident, $v:ident {}) => {};
    ($m:ident, $v:ident { $( $(#[$fm:meta])* $f:ident: $t:ty => ($($rf:ident),+) ),+ $(,)? }) => {
        $( ($($m.$rf),+) = <$t as Recorded<_>>::to_field(&$f); )+
    };
    ($m:ident, $v:ident ( $(#[$fm:meta])* $f:ident: $t:ty => ($($rf:ident),+) )) => {
        ($($m.$rf),+) = <$t as Recorded<_>>::to_field(&$f);
    };
}

/// A row's request from its recorded fields.
macro_rules! req_replay {
    ($m:ident, $v:ident {}) => { Request::$v };
    ($m:ident, $v:ident { $( $(#[$fm:meta])* $f:ident: $t:ty => ($($rf:ident),+) ),+ $(,)? }) => {
        Request::$v { $( $f: <$t as Recorded<_>>::from_field(($($m.$rf),+)), )+ }
    };
    ($m:ident, $v:ident ( $(#[$fm:meta])* $f:ident: $t:ty => ($($rf:ident),+) )) => {
        Request::$v(<$t as Recorded<_>>::from_field(($($m.$rf),+)))
    };
}

/// A row's recorded kind, its `RecordedAs`, what else it records, and the
/// check of its wire code against it.
macro_rules! rec_kind {
    ((as $k:ident if $g:ident)) => {
        CommandKindCode::$k
    };
    (($k:ident = $c:literal $($x:tt)*)) => {
        CommandKindCode::$k
    };
}
macro_rules! rec_as {
    ((as $k:ident if $g:ident)) => {
        RecordedAs::Shared(CommandKindCode::$k, stringify!($g))
    };
    (($k:ident = $c:literal $($x:tt)*)) => {
        RecordedAs::Own(CommandKindCode::$k)
    };
}
macro_rules! rec_extra {
    ($m:ident, $cycle:ident, ($k:ident = $c:literal, with cycle)) => {
        $m.command_arg = $cycle;
    };
    ($m:ident, $cycle:ident, $($x:tt)*) => {};
}
macro_rules! rec_check {
    ($wire:literal, (as $k:ident if $g:ident)) => {
        // Never recorded as itself: apart from every recorded code.
        const _: () = assert!($wire >= 128);
    };
    ($wire:literal, ($k:ident = $c:literal $($x:tt)*)) => {
        // Recorded as itself: its wire code is its recorded code.
        const _: () = assert!($wire == $c);
    };
}
/// The recording's decoder of one row: a row recorded as another kind is
/// tried first (told apart by its field), then the rows recorded as
/// themselves.
macro_rules! rec_shared_arm {
    ($m:ident, (as $k:ident if $g:ident), $v:ident $shape:tt) => {
        if $m.command_kind == CommandKindCode::$k && $m.$g != 0.0 {
            return Some(req_replay!($m, $v $shape));
        }
    };
    ($m:ident, $($x:tt)*) => {};
}
macro_rules! rec_own_arm {
    ($m:ident, ($k:ident = $c:literal $($x:tt)*), $v:ident $shape:tt) => {
        if $m.command_kind == CommandKindCode::$k {
            return Some(req_replay!($m, $v $shape));
        }
    };
    ($m:ident, $($x:tt)*) => {};
}

/// The table's grammar, one row per command:
///
/// ```text
/// requests {                            // stepped by the loop, recorded
///     /// Docs.
///     Name {}                           // no argument
///     Name { arg_unit: Type => (recorded_field), ... }
///     Name(arg: Type => (field_a, field_b))
///         wire WIRE_NAME = code;
///         recorded (Kind = code);       // as itself (`, with cycle`: the cycle in `command_arg`)
///         recorded (as Kind if field);  // as another kind, told apart by `field` != 0
///         log("format", args...);       // the log text (the arguments bound by name)
///         help "one line";
/// }
/// daemon { /// Docs. Name wire WIRE_NAME = code; help "one line"; }
/// legacy { /// Docs. Kind = code; }     // recorded codes no request has now
/// ```
macro_rules! commands {
    (
        requests {$(
            $(#[$doc:meta])*
            $v:ident $shape:tt
            wire $wire:ident = $wcode:literal;
            recorded $rec:tt;
            log($($log:tt)*);
            help $help:literal;
        )*}
        daemon {$(
            $(#[$ddoc:meta])*
            $d:ident wire $dwire:ident = $dcode:literal;
            help $dhelp:literal;
        )*}
        legacy {$(
            $(#[$ldoc:meta])*
            $l:ident = $lcode:literal;
        )*}
    ) => {
        request_enum!([] $( [$(#[$doc])*] $v $shape )*);
        kind_code_enum!([] [$( $(#[$ldoc])* $l = $lcode, )*] $( [$(#[$doc])*] $rec )*);
        $( rec_check!($wcode, $rec); )*
        $( const _: () = assert!(fits(req_slots!($v $shape))); )*
        $( const _: () = assert!($dcode >= 128); )*

        /// The commands answered without the loop (never recorded).
        #[derive(Debug, Clone, Copy, PartialEq, Eq)]
        pub enum DaemonCommand {
            $( $(#[$ddoc])* $d, )*
        }

        /// Command kinds of [`CommandMsg::kind`] (the table's wire codes): a
        /// command the loop steps and records as itself has its recorded
        /// code ([`CommandKindCode`]); the others are 128 and up, apart
        /// from every recorded code (a `uint8` below 128).
        pub mod command_kind {
            $( $(#[$doc])* pub const $wire: u32 = $wcode; )*
            $( $(#[$ddoc])* pub const $dwire: u32 = $dcode; )*
        }

        /// The table as data, row by row.
        pub const COMMANDS: &[CommandInfo] = &[
            $( CommandInfo {
                name: stringify!($v),
                wire: $wcode,
                recorded: rec_as!($rec),
                args: req_args!($v $shape),
                help: $help,
            }, )*
            $( CommandInfo {
                name: stringify!($d),
                wire: $dcode,
                recorded: RecordedAs::NotRecorded,
                args: &[],
                help: $dhelp,
            }, )*
        ];

        impl Request {
            /// Its wire code ([`command_kind`]).
            pub fn wire_code(&self) -> u32 {
                match *self { $( req_any!($v $shape) => $wcode, )* }
            }

            /// Its one-line help.
            pub fn help(&self) -> &'static str {
                match *self { $( req_any!($v $shape) => $help, )* }
            }

            /// It on the wire, with the caller's `id`.
            #[allow(unused_mut)]
            pub fn to_wire(&self, id: u64) -> CommandMsg {
                let mut w = ArgWriter::new();
                let kind = match *self {
                    $( req_pat!($v $shape) => { req_put!(w, $v $shape); $wcode } )*
                };
                CommandMsg { kind, reserved: 0, id, args: w.args }
            }

            /// Writes it into a `/sar/cycle/input` message: its kind, its
            /// unit-named fields ([`CommandLayoutCode::UnitNamed`]) and, for
            /// a reset, the `cycle` that applied it.
            pub fn record(&self, m: &mut CycleInputMsg, cycle: u64) {
                let _ = cycle;
                m.command_layout = CommandLayoutCode::UnitNamed;
                match *self {
                    $( req_pat!($v $shape) => {
                        m.command_kind = rec_kind!($rec);
                        req_record!(m, $v $shape);
                        rec_extra!(m, cycle, $rec);
                    } )*
                }
            }

            /// The request a `/sar/cycle/input` message recorded (a
            /// recording older than issue 36 mapped first,
            /// [`upgraded`]); `None`: none, or a kind no request has now
            /// (a set bias of an older `sard`).
            pub fn from_recorded(recorded: &CycleInputMsg) -> Option<Request> {
                let m = &upgraded(recorded);
                $( rec_shared_arm!(m, $rec, $v $shape); )*
                $( rec_own_arm!(m, $rec, $v $shape); )*
                None
            }
        }

        /// The log's text of a request.
        impl core::fmt::Display for Request {
            fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
                match *self { $( req_pat!($v $shape) => write!(f, $($log)*), )* }
            }
        }

        impl DaemonCommand {
            /// Its wire code ([`command_kind`]).
            pub fn wire_code(self) -> u32 {
                match self { $( Self::$d => $dcode, )* }
            }
            /// It on the wire, with the caller's `id`.
            pub fn to_wire(self, id: u64) -> CommandMsg {
                CommandMsg { kind: self.wire_code(), reserved: 0, id, args: [0.0; COMMAND_ARGS] }
            }
        }

        /// The command a [`CommandMsg`] carries; an unknown kind is an error
        /// naming it. No allocation.
        pub fn decode(c: &CommandMsg) -> Result<WireCommand, CommandError> {
            #[allow(unused_mut, unused_variables)]
            let mut rd = ArgReader { args: &c.args, at: 0 };
            match c.kind {
                $( $wcode => Ok(WireCommand::Loop(req_take!(rd, $v $shape))), )*
                $( $dcode => Ok(WireCommand::Daemon(DaemonCommand::$d)), )*
                kind => Err(CommandError::UnknownKind { kind }),
            }
        }
    };
}

commands! {
    requests {
        /// Leave Stop or Fault (judged on the cycle's input).
        Reset {}
            wire RESET = 1;
            recorded (GuardReset = 1, with cycle);
            log("reset");
            help "leave Stop or Fault (judged on the cycle's input)";

        /// Model-based tare.
        Tare {}
            wire TARE = 2;
            recorded (Tare = 2);
            log("tare");
            help "model-based tare of the force sensor";

        /// Move the tip to this point, base frame, m (inverse kinematics,
        /// then a limited-speed move planned by the loop).
        MoveTip {
            /// The wanted tip, base frame, m.
            tip_m: Vec3 => (move_tip_m),
        }
            wire MOVE_TIP = 10;
            recorded (MoveTip = 10);
            log("move tip to {} m", V3(tip_m));
            help "move the tip to a point of the base frame";

        /// Replace the guard's force limits (within the configured
        /// ceilings).
        SetLimits(limits_n: ForceLimits => (limits_n))
            wire SET_LIMITS = 11;
            recorded (SetLimits = 11);
            log("set limits ({})", limits_n);
            help "set the guard's force limits (within the configured ceilings)";

        /// Back the tip out along the rod by this distance, m (0 < d <=
        /// 0.1): a move to `tip - d u`, accepted in Retreat too (it reduces
        /// the force).
        BackOut {
            /// How far, m.
            distance_m: f64 => (back_out_m),
        }
            wire BACK_OUT = 12;
            recorded (BackOut = 12);
            log("back out {} m", distance_m);
            help "back the tip out along the rod (accepted in Retreat)";

        /// A guarded move (force control, issue 15): as `MoveTip`, but
        /// braked (hard: at `[axes] brake_decel_mps2`, streamed; issue 26)
        /// in the cycle in which the magnitude of the tip force (filtered
        /// when the filter is on) is anticipated to reach `max_force_n`:
        /// the force plus its rise (its rate, low-passed) over the
        /// filter's lag, the drives' lag and the braking, once it is a
        /// quarter of the limit; where and at what force is reported
        /// (`sar_loop::step::LoopOutput::guarded_stop`). Recorded as
        /// `COMMAND_MOVE_TIP` with its force limit.
        GuardedMove {
            /// The wanted tip, base frame, m.
            tip_m: Vec3 => (move_tip_m),
            /// The force that stops it, N (0 < N <= the total stop limit).
            max_force_n: f64 => (move_max_force_n),
        }
            wire GUARDED_MOVE = 131;
            recorded (as MoveTip if move_max_force_n);
            log("guarded move of the tip to {} m, braked at {} N", V3(tip_m), max_force_n);
            help "move the tip, braked when the tip force reaches a limit";

        /// Force control (issue 15, FORCE_CONTROL.md): hold the tip while
        /// the tip force is below `max_force_n`, yield along it above.
        Hold {
            /// N (0 < N <= the total warn limit).
            max_force_n: f64 => (hold_max_force_n),
        }
            wire HOLD = 13;
            recorded (Hold = 13);
            log("force control: hold below {} N", max_force_n);
            help "force control: hold the tip below a force, yield above it";

        /// Force control: regulate the axial tip force to `axial_n`, the
        /// lateral position held.
        Push {
            /// N (0 < N < the axial warn limit).
            axial_n: f64 => (push_axial_n),
        }
            wire PUSH = 14;
            recorded (Push = 14);
            log("force control: push {} N along the rod", axial_n);
            help "force control: regulate the force along the rod";

        /// End force control: hold the tip where it is (position control).
        Position {}
            wire POSITION = 15;
            recorded (Position = 15);
            log("position control");
            help "end force control: the tip holds where it is";

        /// The dynamic identification's excitation about where the axes
        /// rest (issue 26, `sar_loop::excite`).
        Excite(excite: ExciteRequest => (
            excite_amplitude_m, excite_freq_hz, excite_duration_s, excite_fade_s
        ))
            wire EXCITE = 16;
            recorded (Excite = 16);
            log(
                "excitation of {} s (fades {} s): amplitudes {:?} m at {:?} Hz",
                excite.duration_s, excite.fade_s, excite.amplitude_m, excite.freq_hz
            );
            help "the dynamic identification's excitation about where the axes rest";

        /// The operator confirms the support as it is now (issue 34: a named
        /// shift of the support acknowledged; `sarctl support confirm`).
        SupportConfirm {}
            wire SUPPORT_CONFIRM = 17;
            recorded (SupportConfirm = 17);
            log("support confirmed as it is");
            help "confirm the support as it is now (a named shift acknowledged)";
    }
    daemon {
        /// Read the guard's limits (answered without the loop; not
        /// recorded).
        Limits wire LIMITS = 128;
            help "read the guard's force limits";
        /// Start recording (`sarctl record start`; not recorded).
        RecordStart wire RECORD_START = 129;
            help "start the daemon's recording";
        /// Stop recording (`sarctl record stop`; not recorded).
        RecordStop wire RECORD_STOP = 130;
            help "stop the daemon's recording";
    }
    legacy {
        // 3..=8 (`COMMAND_CLEAR_TARE`, `COMMAND_ENABLE`, `COMMAND_DISABLE`,
        // `COMMAND_QUICK_STOP`, `COMMAND_FAULT_RESET`, `COMMAND_MOVE_TO` of
        // the .msg) are reserved: no version of `sard` wrote them.
        /// Set the sensor's bias (values: force x, y, z in N, then torque
        /// x, y, z in N m; sensor frame). Written by older versions of
        /// `sard`; read, it gives no request.
        SetBias = 9;
    }
}

code_enum!(
    /// The layout of a recorded command's arguments (`LAYOUT_*` of
    /// `CycleInput.msg`, issue 36).
    CommandLayoutCode, "command_layout" {
        /// Before issue 36 (and every cycle without a command): EXCITE's
        /// amplitudes in `move_tip_m`, its frequencies, duration and fade
        /// in `limits_n`; HOLD's and PUSH's force in `command_values[0]`.
        Old = 0,
        /// Every argument in its unit-named field (the table's).
        UnitNamed = 1,
    }
);

/// A recorded command in the unit-named layout: an older recording's
/// ([`CommandLayoutCode::Old`]) command re-laid as `sard` records it now
/// (its arguments moved to their fields of now, the fields they borrowed
/// cleared, the layout [`CommandLayoutCode::UnitNamed`]), so that it
/// decodes, and compares byte for byte with a replay's; a cycle without a
/// command, or a message of now, as it is. Frozen history: a new command
/// never needs a line here.
pub fn upgraded(m: &CycleInputMsg) -> CycleInputMsg {
    let mut u = *m;
    if m.command_layout != CommandLayoutCode::Old || m.command_kind == CommandKindCode::None {
        return u;
    }
    u.command_layout = CommandLayoutCode::UnitNamed;
    let [value, ..] = m.command_values;
    match m.command_kind {
        CommandKindCode::Hold => {
            u.hold_max_force_n = value;
            u.command_values[0] = 0.0;
        }
        CommandKindCode::Push => {
            u.push_axial_n = value;
            u.command_values[0] = 0.0;
        }
        CommandKindCode::Excite => {
            let [f1, f2, f3, duration_s, fade_s, _] = m.limits_n;
            u.excite_amplitude_m = m.move_tip_m;
            u.excite_freq_hz = [f1, f2, f3];
            u.excite_duration_s = duration_s;
            u.excite_fade_s = fade_s;
            u.move_tip_m = [0.0; 3];
            u.limits_n = [0.0; 6];
        }
        _ => {}
    }
    u
}
