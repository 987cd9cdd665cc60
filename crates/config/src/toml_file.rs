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
    #[error(
        "{}: cannot read the file: {}",
        shown_origin(origin),
        shown(reason, MAX_PROBLEM_CHARS)
    )]
    Read {
        /// The file.
        origin: String,
        /// The system's reason.
        reason: String,
    },
    /// The file is not valid TOML (toml's message, with line and column).
    #[error(
        "{}: not valid TOML: {}",
        shown_origin(origin),
        shown(message, MAX_PROBLEM_CHARS)
    )]
    Syntax {
        /// The file.
        origin: String,
        /// toml's message.
        message: String,
    },
    /// A key is missing, unknown, of the wrong type, or has a value that is
    /// not allowed.
    #[error(
        "{}: {}{}: {}",
        shown_origin(origin),
        shown(key_or_top(key), MAX_KEY_CHARS),
        line_suffix(*line),
        shown(problem, MAX_PROBLEM_CHARS)
    )]
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

/// The longest problem an error shows, characters (a longer one is cut, so
/// that a value quoted from the file cannot make an error line long).
pub const MAX_PROBLEM_CHARS: usize = 400;
/// The longest key an error shows, characters.
pub const MAX_KEY_CHARS: usize = 64;
/// The longest origin (path) an error shows, characters: a longer one keeps
/// its end, the file's name.
pub const MAX_ORIGIN_CHARS: usize = 160;

/// `text` on one line (control characters as spaces), cut after `max`
/// characters with a note of how many were left out.
fn shown(text: &str, max: usize) -> String {
    let total = text.chars().count();
    let one_line = |c: char| if c.is_control() { ' ' } else { c };
    if total <= max {
        return text.chars().map(one_line).collect();
    }
    let mut out: String = text.chars().take(max).map(one_line).collect();
    out.push_str(&format!("... ({} more characters)", total - max));
    out
}

/// The origin on one line, at most [`MAX_ORIGIN_CHARS`] characters (its end).
fn shown_origin(origin: &str) -> String {
    let total = origin.chars().count();
    let one_line = |c: char| if c.is_control() { ' ' } else { c };
    if total <= MAX_ORIGIN_CHARS {
        return origin.chars().map(one_line).collect();
    }
    let tail: String = origin
        .chars()
        .skip(total - MAX_ORIGIN_CHARS)
        .map(one_line)
        .collect();
    format!("...{tail}")
}

/// A number as an error shows it: plain, or in exponent form when very
/// large or small (`1e308`, never 309 digits).
pub(crate) fn num(v: f64) -> String {
    if v != 0.0 && !(1e-4..1e6).contains(&v.abs()) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

fn key_or_top(key: &str) -> &str {
    if key.is_empty() { "(top level)" } else { key }
}

fn line_suffix(line: Option<usize>) -> String {
    line.map(|l| format!(" (line {l})")).unwrap_or_default()
}

/// The largest configuration or scenario file read, bytes (1 MB). The
/// shipped files are under 10 kB.
pub const MAX_FILE_BYTES: u64 = 1_000_000;

/// The text of the file at `path` and its origin (the path as shown in
/// errors). Only a regular file of at most [`MAX_FILE_BYTES`] is read: the
/// file is opened without blocking (a FIFO without a writer would block the
/// open), its type and size are checked on the open file before a byte is
/// read, and the read itself is bounded (a file that grows meanwhile is
/// refused, never read on).
pub(crate) fn read(path: &Path) -> Result<(String, String), ConfigError> {
    use std::io::Read;
    use std::os::unix::fs::{FileTypeExt, OpenOptionsExt};
    let origin = path.display().to_string();
    let refuse = |reason: String| ConfigError::Read {
        origin: origin.clone(),
        reason,
    };
    let file = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(path)
        .map_err(|e| refuse(e.to_string()))?;
    let meta = file.metadata().map_err(|e| refuse(e.to_string()))?;
    let kind = meta.file_type();
    if !kind.is_file() {
        let what = if kind.is_dir() {
            "a directory"
        } else if kind.is_fifo() {
            "a FIFO"
        } else if kind.is_char_device() {
            "a character device"
        } else if kind.is_block_device() {
            "a block device"
        } else if kind.is_socket() {
            "a socket"
        } else {
            "not a file"
        };
        return Err(refuse(format!("not a regular file ({what})")));
    }
    let too_big = |bytes: String| {
        refuse(format!(
            "{bytes} bytes, more than 1 MB ({MAX_FILE_BYTES} bytes): not a configuration or \
             scenario file"
        ))
    };
    if meta.len() > MAX_FILE_BYTES {
        return Err(too_big(meta.len().to_string()));
    }
    let mut bytes = Vec::new();
    file.take(MAX_FILE_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| refuse(e.to_string()))?;
    if bytes.len() as u64 > MAX_FILE_BYTES {
        return Err(too_big(format!("at least {}", bytes.len())));
    }
    let text = String::from_utf8(bytes).map_err(|e| {
        refuse(format!(
            "not UTF-8 text (an invalid byte at offset {})",
            e.utf8_error().valid_up_to()
        ))
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
    let root = toml::de::DeTable::parse(text).map_err(|e| ConfigError::Syntax {
        origin: origin.to_owned(),
        message: syntax_message(text, &e),
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

/// toml's syntax error as one line: "line L, column C: " and toml's message
/// (without the file's line itself, which can be long).
fn syntax_message(text: &str, e: &toml::de::Error) -> String {
    let message = e
        .message()
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .collect::<Vec<_>>()
        .join(", ");
    match e.span() {
        Some(span) => {
            let before = text.get(..span.start).unwrap_or(text);
            let line = 1 + before.bytes().filter(|&b| b == b'\n').count();
            let line_start = before.rfind('\n').map_or(0, |i| i + 1);
            let column = 1 + before.get(line_start..).unwrap_or("").chars().count();
            format!("line {line}, column {column}: {message}")
        }
        None => message,
    }
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
