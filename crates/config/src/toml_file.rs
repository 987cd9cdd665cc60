//! A TOML file being checked, shared by the configuration and the scenario
//! loaders: the one error type ([`ConfigError`]: file, dotted key, line,
//! problem), reading and parsing (toml's syntax errors keep its line and
//! column; NaN and infinity refused under their key; serde's errors mapped
//! to the key and its line) and the context ([`Ctx`]) that makes the errors
//! of the checks that follow.

use crate::locate::Locator;
use serde::de::DeserializeOwned;
use std::path::Path;

/// A file that cannot be used (a configuration or a scenario). The message
/// names the file, the key (dotted, e.g. `guard.stop_total_n` or
/// `motion[3].hold_s`), the line when the file writes the key, and what is
/// wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ConfigError {
    /// The file could not be read.
    #[error("{origin}: cannot read the file: {reason}")]
    Read {
        /// The file.
        origin: String,
        /// The system's reason.
        reason: String,
    },
    /// The file is not valid TOML (toml's message, with line and column).
    #[error("{origin}: not valid TOML: {message}")]
    Syntax {
        /// The file.
        origin: String,
        /// toml's message.
        message: String,
    },
    /// A key is missing, unknown, of the wrong type, or has a value that is
    /// not allowed.
    #[error("{origin}: {}{}: {problem}", key_or_top(key), line_suffix(*line))]
    Invalid {
        /// The file.
        origin: String,
        /// The dotted key ("" for the file as a whole).
        key: String,
        /// The 1-based line where the key (or its table) is written.
        line: Option<usize>,
        /// What is wrong.
        problem: String,
    },
}

impl ConfigError {
    /// The file (or origin) the error is about.
    pub fn origin(&self) -> &str {
        match self {
            Self::Read { origin, .. }
            | Self::Syntax { origin, .. }
            | Self::Invalid { origin, .. } => origin,
        }
    }

    /// The dotted key, for [`ConfigError::Invalid`].
    pub fn key(&self) -> Option<&str> {
        match self {
            Self::Invalid { key, .. } => Some(key),
            _ => None,
        }
    }

    /// The line, for [`ConfigError::Invalid`] when the file writes the key.
    pub fn line(&self) -> Option<usize> {
        match self {
            Self::Invalid { line, .. } => *line,
            _ => None,
        }
    }
}

fn key_or_top(key: &str) -> &str {
    if key.is_empty() { "(top level)" } else { key }
}

fn line_suffix(line: Option<usize>) -> String {
    line.map(|l| format!(" (line {l})")).unwrap_or_default()
}

/// The text of the file at `path` and its origin (the path as shown in errors).
pub(crate) fn read(path: &Path) -> Result<(String, String), ConfigError> {
    let origin = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| ConfigError::Read {
        origin: origin.clone(),
        reason: e.to_string(),
    })?;
    Ok((text, origin))
}

/// Parses `text` as the file's shape `T`: toml's syntax, then no NaN or
/// infinite float anywhere, then serde (unknown keys refused by `T`). Gives
/// the context that makes the errors of the checks that follow.
pub(crate) fn parse<'a, T: DeserializeOwned>(
    text: &'a str,
    origin: &'a str,
) -> Result<(Ctx<'a>, T), ConfigError> {
    let root = toml::de::DeTable::parse(text).map_err(|e| {
        let mut e = e;
        e.set_input(Some(text));
        ConfigError::Syntax {
            origin: origin.to_owned(),
            message: e.to_string().trim_end().to_owned(),
        }
    })?;
    let ctx = Ctx {
        origin,
        locator: Locator::new(text, &root),
    };
    // NaN and infinity are valid TOML floats; no value of these files may be one.
    if let Some((key, line)) = ctx.locator.first_non_finite() {
        return Err(ConfigError::Invalid {
            origin: origin.to_owned(),
            key,
            line: Some(line),
            problem: "not a finite number".to_owned(),
        });
    }
    let file: T = serde::Deserialize::deserialize(toml::de::Deserializer::from(root))
        .map_err(|e| ctx.serde_error(&e))?;
    Ok((ctx, file))
}

/// The file being checked: makes errors that name it, the key and the line.
/// Each loader adds the checks its keys share (`impl Ctx` in its module).
pub(crate) struct Ctx<'a> {
    /// The file (or origin) named in errors.
    pub origin: &'a str,
    /// Where each key is written.
    pub locator: Locator<'a>,
}

impl Ctx<'_> {
    /// `problem` with `key`, at the line of the key or of its nearest
    /// enclosing key that the file writes.
    pub fn err(&self, key: &str, problem: impl Into<String>) -> ConfigError {
        ConfigError::Invalid {
            origin: self.origin.to_owned(),
            key: key.to_owned(),
            line: self.locator.line_near(key),
            problem: problem.into(),
        }
    }

    /// A serde error of the file, with its key and line.
    fn serde_error(&self, e: &toml::de::Error) -> ConfigError {
        let (key, line, problem) = self.locator.serde_problem(e);
        ConfigError::Invalid {
            origin: self.origin.to_owned(),
            key,
            line,
            problem,
        }
    }
}
