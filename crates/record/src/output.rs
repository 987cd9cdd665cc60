//! The files the tools write (`sarctl replay --output`, `recover`, a
//! `--plot`): never one of their inputs, never a file cut in place.
//!
//! - [`check_outputs`]: each output is compared by (device, inode) with
//!   every input, and with the other outputs: a hard link or a symbolic
//!   link to an input is the input (a path comparison missed both).
//! - [`PendingFile`]: an output is written to a temporary file in its own
//!   directory and renamed over its path only once complete
//!   ([`PendingFile::commit`]); a write that fails or is refused removes
//!   the temporary file, so an existing file at the path (an input by a
//!   name the check could not see, or an older output) is never truncated
//!   or left half written.
//! - [`SpaceWatch`]: the free space of the output's file system
//!   (`statvfs`, the blocks available to the user) checked before anything
//!   is written (at least the inputs' length must be free beyond the
//!   reserve) and every [`CHECK_EVERY_BYTES`] (at most a quarter of the reserve)
//!   while writing: an output
//!   that would leave less than [`reserve_bytes`] free stops with
//!   [`OutputError::NoSpace`] (a crafted lean recording expands 1,500 times
//!   in its replay; the disk may hold the daemon's recordings).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// Why an output cannot be written.
#[non_exhaustive]
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// The output is one of the inputs (the same file, by any name).
    #[error("{output}: refusing to write over the input {input}{how}: give another output")]
    IsInput {
        /// The output's path.
        output: PathBuf,
        /// The input's path.
        input: PathBuf,
        /// How they are the same ("" when the paths are equal).
        how: &'static str,
    },
    /// Two outputs of one command are the same file.
    #[error("{first} and {second} are the same file: give each output its own path")]
    SameOutputs {
        /// One output.
        first: PathBuf,
        /// The other.
        second: PathBuf,
    },
    /// The output's directory or its temporary file could not be used.
    #[error("{path}: {source}")]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// Writing on would leave less than the reserve free.
    #[error(
        "{path}: {} free on its file system{}; at least {} must stay free ({}): nothing written in its place",
        mb(*free_bytes),
        if *written_bytes > 0 { format!(" after {} written", mb(*written_bytes)) } else { format!(", the output needs at least {}", mb(*needed_bytes)) },
        mb(*reserve_bytes),
        if *written_bytes > 0 { "stopped while writing" } else { "refused before writing" }
    )]
    NoSpace {
        /// The output.
        path: PathBuf,
        /// Bytes available on its file system.
        free_bytes: u64,
        /// Bytes it needs at least (before writing: the estimate).
        needed_bytes: u64,
        /// Bytes written when it stopped (0: before writing).
        written_bytes: u64,
        /// Bytes kept free.
        reserve_bytes: u64,
    },
}

/// Bytes as GB, MB or kB (powers of 10), one decimal.
fn mb(bytes: u64) -> String {
    let b = bytes as f64;
    if b >= 1e9 {
        format!("{:.1} GB", b / 1e9)
    } else if b >= 1e6 {
        format!("{:.1} MB", b / 1e6)
    } else {
        format!("{:.1} kB", b / 1e3)
    }
}

/// A file's identity: (device, inode), following symbolic links.
fn identity(path: &Path) -> Option<(u64, u64)> {
    use std::os::unix::fs::MetadataExt;
    std::fs::metadata(path).ok().map(|m| (m.dev(), m.ino()))
}

/// Where a path that may not exist yet lives: its directory resolved
/// (symbolic links followed) and its name.
fn resolved(path: &Path) -> Option<PathBuf> {
    let name = path.file_name()?;
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    Some(std::fs::canonicalize(dir).ok()?.join(name))
}

/// Refuses an output that is one of the inputs (by (device, inode): a
/// hard link, a symbolic link or another spelling of an input is the
/// input), or two outputs that are the same file.
pub fn check_outputs(outputs: &[&Path], inputs: &[&Path]) -> Result<(), OutputError> {
    for output in outputs {
        let out_id = identity(output);
        for input in inputs {
            let how = if output == input {
                Some("")
            } else if out_id.is_some() && out_id == identity(input) {
                Some(" (the same file by another name: a hard or symbolic link)")
            } else {
                None
            };
            if let Some(how) = how {
                return Err(OutputError::IsInput {
                    output: output.to_path_buf(),
                    input: input.to_path_buf(),
                    how,
                });
            }
        }
    }
    for (i, first) in outputs.iter().enumerate() {
        for second in outputs.iter().skip(i + 1) {
            let same = first == second
                || identity(first).is_some_and(|a| Some(a) == identity(second))
                || resolved(first).is_some_and(|a| Some(a) == resolved(second));
            if same {
                return Err(OutputError::SameOutputs {
                    first: first.to_path_buf(),
                    second: second.to_path_buf(),
                });
            }
        }
    }
    Ok(())
}

/// An output under way: written to [`PendingFile::tmp_path`] (in the
/// output's directory, so that the rename is atomic), renamed over the
/// output by [`PendingFile::commit`]; dropped uncommitted, the temporary
/// file is removed.
#[derive(Debug)]
pub struct PendingFile {
    path: PathBuf,
    tmp: PathBuf,
    committed: bool,
}

/// Tells the temporary files of one process apart.
static TMP_COUNTER: AtomicU64 = AtomicU64::new(0);

impl PendingFile {
    /// The output `path`, its temporary file named beside it
    /// (`.NAME.PID-N.tmp`, not created yet).
    pub fn new(path: &Path) -> Result<Self, OutputError> {
        let name = path.file_name().ok_or_else(|| OutputError::Io {
            path: path.to_path_buf(),
            source: std::io::Error::new(std::io::ErrorKind::InvalidInput, "not a file name"),
        })?;
        let n = TMP_COUNTER.fetch_add(1, Ordering::Relaxed);
        let tmp = path.with_file_name(format!(
            ".{}.{}-{n}.tmp",
            name.to_string_lossy(),
            std::process::id()
        ));
        Ok(Self {
            path: path.to_path_buf(),
            tmp,
            committed: false,
        })
    }

    /// The output's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Where to write.
    pub fn tmp_path(&self) -> &Path {
        &self.tmp
    }

    /// The temporary file (once written) synced and renamed over the
    /// output. Nothing written: nothing renamed, `Ok(false)`.
    pub fn commit(mut self) -> Result<bool, OutputError> {
        let io = |path: &Path| {
            let path = path.to_path_buf();
            move |source| OutputError::Io { path, source }
        };
        if !self.tmp.exists() {
            self.committed = true;
            return Ok(false);
        }
        std::fs::File::open(&self.tmp)
            .and_then(|f| f.sync_all())
            .map_err(io(&self.tmp))?;
        std::fs::rename(&self.tmp, &self.path).map_err(io(&self.path))?;
        self.committed = true;
        Ok(true)
    }
}

impl Drop for PendingFile {
    fn drop(&mut self) {
        if !self.committed {
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}

/// Free space is checked again after each this many bytes written.
pub const CHECK_EVERY_BYTES: u64 = 8 * 1024 * 1024;

/// The most kept free on any file system ([`reserve_bytes`]).
pub const RESERVE_MAX_BYTES: u64 = 256 * 1024 * 1024;

/// What an output leaves free on a file system of `total_bytes`: a
/// twentieth of it, at most [`RESERVE_MAX_BYTES`].
pub fn reserve_bytes(total_bytes: u64) -> u64 {
    (total_bytes / 20).min(RESERVE_MAX_BYTES)
}

/// (available to the user, total) bytes of the file system holding `dir`.
#[allow(unsafe_code)]
pub fn space_of(dir: &Path) -> std::io::Result<(u64, u64)> {
    use std::os::unix::ffi::OsStrExt;
    let c = std::ffi::CString::new(dir.as_os_str().as_bytes())
        .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidInput, e))?;
    // SAFETY: `c` is a valid NUL-terminated path; `vfs` is written by the
    // call before it is read (zeroed: a plain C struct).
    let mut vfs: libc::statvfs = unsafe { std::mem::zeroed() };
    if unsafe { libc::statvfs(c.as_ptr(), &mut vfs) } != 0 {
        return Err(std::io::Error::last_os_error());
    }
    // (u64 on 64-bit Linux, narrower elsewhere.)
    #[allow(clippy::useless_conversion)]
    let frsize = u64::from(vfs.f_frsize);
    #[allow(clippy::useless_conversion)]
    let (avail, blocks) = (u64::from(vfs.f_bavail), u64::from(vfs.f_blocks));
    Ok((avail.saturating_mul(frsize), blocks.saturating_mul(frsize)))
}

/// The free space of an output's file system, watched while it is
/// written.
#[derive(Debug)]
pub struct SpaceWatch {
    path: PathBuf,
    dir: PathBuf,
    /// The file being written (its length on disk: what the kernel has of
    /// what was written; the rest is still in the writer's buffer).
    file: PathBuf,
    /// Checked every this many bytes: at most [`CHECK_EVERY_BYTES`], at
    /// most a quarter of the reserve (never past the reserve between two checks).
    every_bytes: u64,
    next_check_bytes: u64,
}

impl SpaceWatch {
    /// Checks before writing `path` (into `file`, its temporary file) that
    /// its file system has `needed_bytes` free beyond [`reserve_bytes`].
    pub fn before(path: &Path, file: &Path, needed_bytes: u64) -> Result<Self, OutputError> {
        let dir = match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let (_, total) = space_of(&dir).map_err(|source| OutputError::Io {
            path: dir.clone(),
            source,
        })?;
        let every_bytes = (reserve_bytes(total) / 4).clamp(16 * 1024, CHECK_EVERY_BYTES);
        let watch = Self {
            path: path.to_path_buf(),
            dir,
            file: file.to_path_buf(),
            every_bytes,
            next_check_bytes: every_bytes,
        };
        watch.check(0, needed_bytes)?;
        Ok(watch)
    }

    /// After `written_bytes` written in all: checked again every
    /// [`CHECK_EVERY_BYTES`] or a quarter of the reserve (a `statvfs` each time).
    pub fn written(&mut self, written_bytes: u64) -> Result<(), OutputError> {
        if written_bytes < self.next_check_bytes {
            return Ok(());
        }
        self.next_check_bytes = written_bytes.saturating_add(self.every_bytes);
        self.check(written_bytes, 0)
    }

    fn check(&self, written_bytes: u64, needed_bytes: u64) -> Result<(), OutputError> {
        let (free_bytes, total) = space_of(&self.dir).map_err(|source| OutputError::Io {
            path: self.dir.clone(),
            source,
        })?;
        // What the writer holds in its buffer will take space too.
        let on_disk = std::fs::metadata(&self.file).map_or(0, |m| m.len());
        let free_bytes = free_bytes.saturating_sub(written_bytes.saturating_sub(on_disk));
        let reserve = reserve_bytes(total);
        if free_bytes < reserve.saturating_add(needed_bytes) {
            return Err(OutputError::NoSpace {
                path: self.path.clone(),
                free_bytes,
                needed_bytes,
                written_bytes,
                reserve_bytes: reserve,
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::indexing_slicing)]
    use super::*;

    fn dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("sar-output-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn a_link_to_an_input_is_the_input_and_outputs_differ() {
        let d = dir("links");
        let input = d.join("rec.mcap");
        std::fs::write(&input, b"recording").unwrap();
        let hard = d.join("hard.mcap");
        std::fs::hard_link(&input, &hard).unwrap();
        let soft = d.join("soft.mcap");
        std::os::unix::fs::symlink(&input, &soft).unwrap();
        let dotted = d.join(".").join("rec.mcap");
        for out in [&input, &hard, &soft, &dotted] {
            let e = check_outputs(&[out], &[&input]).unwrap_err();
            assert!(matches!(e, OutputError::IsInput { .. }), "{e}");
            assert!(
                e.to_string().contains("refusing to write over the input"),
                "{e}"
            );
        }
        let new = d.join("new.mcap");
        check_outputs(&[&new], &[&input]).unwrap();
        // Two outputs, one of them not yet there, by two spellings.
        let e = check_outputs(&[&new, &d.join(".").join("new.mcap")], &[&input]).unwrap_err();
        assert!(matches!(e, OutputError::SameOutputs { .. }), "{e}");
    }

    #[test]
    fn a_pending_file_replaces_the_path_only_when_committed() {
        let d = dir("pending");
        let path = d.join("out.mcap");
        std::fs::write(&path, b"old").unwrap();
        let p = PendingFile::new(&path).unwrap();
        std::fs::write(p.tmp_path(), b"new").unwrap();
        let tmp = p.tmp_path().to_path_buf();
        drop(p);
        assert!(!tmp.exists());
        assert_eq!(std::fs::read(&path).unwrap(), b"old");
        let p = PendingFile::new(&path).unwrap();
        std::fs::write(p.tmp_path(), b"new").unwrap();
        assert!(p.commit().unwrap());
        assert_eq!(std::fs::read(&path).unwrap(), b"new");
        // Nothing written: nothing renamed.
        assert!(!PendingFile::new(&d.join("none")).unwrap().commit().unwrap());
        assert!(!d.join("none").exists());
    }

    #[test]
    fn the_reserve_is_a_twentieth_at_most_256_mib() {
        assert_eq!(reserve_bytes(1 << 20), (1 << 20) / 20);
        assert_eq!(reserve_bytes(1 << 40), RESERVE_MAX_BYTES);
        // This machine's temporary directory: a need beyond its size is
        // refused before writing, naming the space.
        let d = dir("space");
        let (_, total) = space_of(&d).unwrap();
        let e = SpaceWatch::before(&d.join("x"), &d.join("x"), total).unwrap_err();
        assert!(e.to_string().contains("refused before writing"), "{e}");
        SpaceWatch::before(&d.join("x"), &d.join("x"), 0).unwrap();
    }
}
