//! The access model (issue 25): where the daemon and its clients meet, who
//! may, and the checks made before iceoryx2 is called.
//!
//! Every iceoryx2 file of a daemon lives in its runtime directory
//! ([`DEFAULT_RUNTIME_DIR`], or `SAR_RUNTIME_DIR`): under systemd
//! `RuntimeDirectory=sar`, owned by the daemon's user and its group `sar`,
//! mode 2770 (set-group-ID). The daemon's user and the members of the directory's group
//! (the operators) read and command; nobody else can enter the directory,
//! so nobody else can read, command, create or damage anything there.
//!
//! - The daemon creates the directory when it is missing (mode 2770), refuses
//!   one that is not a directory or belongs to another user, and takes the
//!   other users' access away when the mode gives them any.
//! - A client never creates it: a missing directory means no daemon runs;
//!   one it may not enter is refused at once, naming the user and the group.
//! - Both check iceoryx2's management file before creating a node: a
//!   truncated or foreign one made iceoryx2 spin forever (finding 2).
//!
//! The `unsafe` here: `libc` calls (user and group names, `faccessat`,
//! `getgroups`) on buffers owned by the caller.
#![allow(unsafe_code)]

use crate::ShmError;
use std::ffi::CString;
use std::os::unix::ffi::OsStrExt;
use std::os::unix::fs::{MetadataExt, PermissionsExt};
use std::path::{Path, PathBuf};

/// The runtime directory when `SAR_RUNTIME_DIR` is not set (systemd's
/// `RuntimeDirectory=sar`).
pub const DEFAULT_RUNTIME_DIR: &str = "/run/sar";
/// The environment variable that names the runtime directory (the daemon and
/// its clients must agree; tests give each daemon its own).
pub const RUNTIME_DIR_ENV: &str = "SAR_RUNTIME_DIR";
/// The mode the daemon gives a runtime directory it creates: the user's and
/// the group's, and set-group-ID, so that every file in it (an operator's
/// too) belongs to the directory's group.
pub const RUNTIME_DIR_MODE: u32 = 0o2770;
/// How the name of iceoryx2's management segment in the runtime directory
/// ends (iceoryx2 0.10: `iox2_<hash>_node.0_10_0.global_mgmt`).
pub const GLOBAL_MGMT_SUFFIX: &str = ".global_mgmt";
/// The size of a healthy management segment, bytes (a version and a node
/// counter; checked by a test against the file iceoryx2 writes).
pub const GLOBAL_MGMT_SIZE: u64 = 16;

/// The first 8 bytes of a healthy management segment: iceoryx2's version
/// (0.10.0: major << 32 | minor << 16 | patch), little-endian.
pub const GLOBAL_MGMT_VERSION: u64 = 10 << 16;

/// The runtime directory: `SAR_RUNTIME_DIR` when set; else
/// [`DEFAULT_RUNTIME_DIR`] when it exists (a daemon under systemd) or for
/// root; else, for a user without it (a developer's `sard --sim` and its
/// `sarctl`), `$XDG_RUNTIME_DIR/sar` when that is set; else
/// [`DEFAULT_RUNTIME_DIR`].
pub fn runtime_dir() -> PathBuf {
    if let Some(d) = std::env::var_os(RUNTIME_DIR_ENV).filter(|d| !d.is_empty()) {
        return PathBuf::from(d);
    }
    let default = PathBuf::from(DEFAULT_RUNTIME_DIR);
    if euid() == 0 || std::fs::symlink_metadata(&default).is_ok() {
        return default;
    }
    match std::env::var_os("XDG_RUNTIME_DIR").filter(|d| !d.is_empty()) {
        Some(x) => PathBuf::from(x).join("sar"),
        None => default,
    }
}

/// Who asks: the daemon may create and repair the directory, a client not.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    /// `sard`.
    Daemon,
    /// `sarctl` and every other client.
    Client,
}

/// A user's name, or its number when it has none.
pub fn user_name(uid: u32) -> String {
    let mut buf = vec![0u8; 4096];
    // SAFETY: a plain C struct; all-zero is a valid value.
    let mut pwd: libc::passwd = unsafe { std::mem::zeroed() };
    let mut out: *mut libc::passwd = std::ptr::null_mut();
    // SAFETY: buffers owned here, sizes given; `out` is null or `&pwd`.
    let rc =
        unsafe { libc::getpwuid_r(uid, &mut pwd, buf.as_mut_ptr().cast(), buf.len(), &mut out) };
    if rc == 0 && !out.is_null() && !pwd.pw_name.is_null() {
        // SAFETY: a NUL-terminated string inside `buf`.
        let name = unsafe { std::ffi::CStr::from_ptr(pwd.pw_name) };
        return name.to_string_lossy().into_owned();
    }
    format!("uid {uid}")
}

/// A group's name, or its number when it has none.
pub fn group_name(gid: u32) -> String {
    let mut buf = vec![0u8; 4096];
    // SAFETY: a plain C struct; all-zero is a valid value.
    let mut grp: libc::group = unsafe { std::mem::zeroed() };
    let mut out: *mut libc::group = std::ptr::null_mut();
    // SAFETY: as in `user_name`.
    let rc =
        unsafe { libc::getgrgid_r(gid, &mut grp, buf.as_mut_ptr().cast(), buf.len(), &mut out) };
    if rc == 0 && !out.is_null() && !grp.gr_name.is_null() {
        // SAFETY: a NUL-terminated string inside `buf`.
        let name = unsafe { std::ffi::CStr::from_ptr(grp.gr_name) };
        return name.to_string_lossy().into_owned();
    }
    format!("gid {gid}")
}

/// Whether this process may `mode` (`libc::R_OK` ...) `path`, by its
/// effective ids; `Err` carries the OS error.
fn may(path: &Path, mode: libc::c_int) -> std::io::Result<()> {
    let c = CString::new(path.as_os_str().as_bytes())
        .map_err(|_| std::io::Error::from(std::io::ErrorKind::InvalidInput))?;
    // SAFETY: a valid NUL-terminated path.
    let rc = unsafe { libc::faccessat(libc::AT_FDCWD, c.as_ptr(), mode, libc::AT_EACCESS) };
    if rc == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}

/// Whether this process is in group `gid` (effective or supplementary).
fn in_group(gid: u32) -> bool {
    // SAFETY: plain queries.
    if unsafe { libc::getegid() } == gid {
        return true;
    }
    let n = unsafe { libc::getgroups(0, std::ptr::null_mut()) };
    if n <= 0 {
        return false;
    }
    let mut groups = vec![0 as libc::gid_t; n as usize];
    // SAFETY: `groups` holds `n` entries.
    let n = unsafe { libc::getgroups(n, groups.as_mut_ptr()) };
    groups.iter().take(n.max(0) as usize).any(|g| *g == gid)
}

fn euid() -> u32 {
    // SAFETY: a plain query.
    unsafe { libc::geteuid() }
}

fn dir_error(dir: &Path, detail: impl Into<String>) -> ShmError {
    ShmError::RuntimeDir {
        dir: dir.display().to_string(),
        detail: detail.into(),
    }
}

/// Checks (the daemon: creates or repairs) the runtime directory before
/// iceoryx2 touches it, then its management file.
pub fn prepare(dir: &Path, side: Side) -> Result<(), ShmError> {
    let meta = match std::fs::symlink_metadata(dir) {
        Ok(m) => m,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => match side {
            Side::Client => {
                return Err(ShmError::NoRuntimeDir {
                    dir: dir.display().to_string(),
                });
            }
            Side::Daemon => {
                // Never open to others, not even before the mode is set (a
                // daemon making it at the same moment is no error).
                use std::os::unix::fs::DirBuilderExt;
                match std::fs::DirBuilder::new().mode(0o770).create(dir) {
                    Ok(()) => std::fs::set_permissions(
                        dir,
                        std::fs::Permissions::from_mode(RUNTIME_DIR_MODE),
                    )
                    .map_err(|e| dir_error(dir, format!("cannot set its mode: {e}")))?,
                    Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
                    Err(e) => return Err(dir_error(dir, format!("cannot create it: {e}"))),
                }
                std::fs::symlink_metadata(dir)
                    .map_err(|e| dir_error(dir, format!("cannot read it: {e}")))?
            }
        },
        Err(e) if e.kind() == std::io::ErrorKind::PermissionDenied => {
            return Err(denied(dir, None));
        }
        Err(e) => return Err(dir_error(dir, format!("cannot read it: {e}"))),
    };
    if !meta.file_type().is_dir() {
        return Err(dir_error(dir, "not a directory"));
    }
    let me = euid();
    if side == Side::Daemon {
        if meta.uid() != me {
            return Err(dir_error(
                dir,
                format!(
                    "it belongs to {}, not to sard's user {}: remove it, or start sard as its owner",
                    user_name(meta.uid()),
                    user_name(me)
                ),
            ));
        }
        if meta.mode() & 0o007 != 0 {
            // Other users keep nothing: the directory is the fence.
            std::fs::set_permissions(dir, std::fs::Permissions::from_mode(meta.mode() & 0o7770))
                .map_err(|e| {
                    dir_error(dir, format!("cannot take other users' access away: {e}"))
                })?;
            tracing::warn!(
                "{}: took other users' access away (mode {:04o} -> {:04o})",
                dir.display(),
                meta.mode() & 0o7777,
                meta.mode() & 0o7770
            );
        }
    }
    if may(dir, libc::R_OK | libc::W_OK | libc::X_OK).is_err() {
        return Err(denied(dir, Some(&meta)));
    }
    check_mgmt(dir)
}

/// Takes every access of other users away from the files and directories
/// of this process's user in the runtime directory `dir` (two levels: the
/// files, `nodes/*`, `services/*`) that belong to the directory's group
/// (a file of another group stays as it is: its group's access would not
/// be the directory's). iceoryx2 (`dev_permissions`) makes them 0666 and
/// 0777; the directory already keeps others out, this keeps a file that
/// leaves it (a hard link made elsewhere by a member) closed to them too.
/// The daemon's publishing thread calls it every [`FENCE_PERIOD`], a client
/// after making its ports. Returns how many it changed (at most `limit`
/// entries are looked at).
pub fn fence_own_files(dir: &Path, limit: usize) -> usize {
    let me = euid();
    let Ok(group) = std::fs::metadata(dir).map(|m| m.gid()) else {
        return 0;
    };
    let mut seen = 0;
    let mut changed = 0;
    let visit = |path: &Path, changed: &mut usize| {
        let Ok(m) = std::fs::symlink_metadata(path) else {
            return false;
        };
        if m.uid() == me && m.gid() == group && !m.file_type().is_symlink() && m.mode() & 0o007 != 0
        {
            let mode = m.mode() & 0o7770;
            if std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode)).is_ok() {
                *changed += 1;
            }
        }
        m.file_type().is_dir()
    };
    let Ok(top) = std::fs::read_dir(dir) else {
        return 0;
    };
    for entry in top.flatten() {
        seen += 1;
        if seen > limit {
            break;
        }
        let path = entry.path();
        if visit(&path, &mut changed) {
            let Ok(inner) = std::fs::read_dir(&path) else {
                continue;
            };
            for e in inner.flatten() {
                seen += 1;
                if seen > limit {
                    break;
                }
                let p = e.path();
                if visit(&p, &mut changed)
                    && let Ok(deep) = std::fs::read_dir(&p)
                {
                    for f in deep.flatten() {
                        seen += 1;
                        if seen > limit {
                            break;
                        }
                        visit(&f.path(), &mut changed);
                    }
                }
            }
        }
    }
    changed
}

/// How often the daemon takes other users' access away from its new files.
pub const FENCE_PERIOD: std::time::Duration = std::time::Duration::from_secs(1);
/// Entries a fence looks at, at most (a directory flooded by a member does
/// not hold the publishing thread).
pub const FENCE_LIMIT: usize = 4096;

/// Whether `dir` is on a memory file system (tmpfs, ramfs): elsewhere the
/// shared memory's pages are written back to a disk.
pub fn on_tmpfs(dir: &Path) -> bool {
    const TMPFS_MAGIC: i64 = 0x0102_1994;
    const RAMFS_MAGIC: i64 = 0x8584_58f6;
    let Ok(c) = CString::new(dir.as_os_str().as_bytes()) else {
        return false;
    };
    // SAFETY: a plain C struct; all-zero is a valid value.
    let mut st: libc::statfs = unsafe { std::mem::zeroed() };
    // SAFETY: a valid path and a buffer of the right type.
    if unsafe { libc::statfs(c.as_ptr(), &mut st) } != 0 {
        return false;
    }
    #[allow(clippy::unnecessary_cast, clippy::cast_lossless)]
    let kind = st.f_type as i64;
    kind == TMPFS_MAGIC || kind == RAMFS_MAGIC
}

/// A client (or a daemon) that may not use the directory: who, and why.
fn denied(dir: &Path, meta: Option<&std::fs::Metadata>) -> ShmError {
    let user = user_name(euid());
    let detail = match meta {
        Some(m) if !in_group(m.gid()) => format!(
            "user {user} is not in group {} (the group of {}; an administrator adds an operator with `usermod -aG {} {user}`)",
            group_name(m.gid()),
            dir.display(),
            group_name(m.gid())
        ),
        Some(m) => format!(
            "{} (mode {:04o}) gives its group {} no read, write and search access",
            dir.display(),
            m.mode() & 0o7777,
            group_name(m.gid())
        ),
        None => format!("user {user} may not enter a parent of {}", dir.display()),
    };
    ShmError::PermissionDenied { detail }
}

/// iceoryx2's management segment, when present, must be a regular file of
/// the right size that this process may read and write: iceoryx2 spins
/// forever on an empty one and faults on a short one.
fn check_mgmt(dir: &Path) -> Result<(), ShmError> {
    let entries =
        std::fs::read_dir(dir).map_err(|e| dir_error(dir, format!("cannot list it: {e}")))?;
    // Bounded like the fence: a directory filled with files (clients killed
    // before they could clean up) costs at most FENCE_LIMIT entries here.
    for entry in entries.flatten().take(FENCE_LIMIT) {
        if entry
            .file_name()
            .as_bytes()
            .ends_with(GLOBAL_MGMT_SUFFIX.as_bytes())
        {
            check_mgmt_file(&entry.path())?;
        }
    }
    Ok(())
}

fn check_mgmt_file(path: &Path) -> Result<(), ShmError> {
    let meta = match std::fs::symlink_metadata(path) {
        Ok(m) => m,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(e) => return Err(damaged(path, format!("cannot read it: {e}"))),
    };
    if !meta.file_type().is_file() {
        return Err(damaged(path, "not a regular file".to_owned()));
    }
    if meta.len() != GLOBAL_MGMT_SIZE {
        return Err(damaged(
            path,
            format!("{} bytes, not {GLOBAL_MGMT_SIZE}", meta.len()),
        ));
    }
    if may(path, libc::R_OK | libc::W_OK).is_err() {
        return Err(damaged(
            path,
            format!(
                "owned by {} with mode {:04o}: {} may not read and write it",
                user_name(meta.uid()),
                meta.mode() & 0o7777,
                user_name(euid())
            ),
        ));
    }
    // Opened without following a link and without blocking (a member of
    // the group may swap the file for a FIFO or a link after the check
    // above), then checked again on the open file.
    let mut version = [0u8; 8];
    {
        use std::os::unix::fs::OpenOptionsExt;
        let mut file = std::fs::OpenOptions::new()
            .read(true)
            .custom_flags(libc::O_NONBLOCK | libc::O_NOFOLLOW)
            .open(path)
            .map_err(|e| damaged(path, format!("cannot open it: {e}")))?;
        let opened = file
            .metadata()
            .map_err(|e| damaged(path, format!("cannot read it: {e}")))?;
        if !opened.file_type().is_file() || opened.len() != GLOBAL_MGMT_SIZE {
            return Err(damaged(path, "changed while it was checked".to_owned()));
        }
        std::io::Read::read_exact(&mut file, &mut version)
            .map_err(|e| damaged(path, format!("cannot read it: {e}")))?;
    }
    let version = u64::from_le_bytes(version);
    if version != GLOBAL_MGMT_VERSION {
        return Err(damaged(
            path,
            format!("version field {version:#x}, not iceoryx2 0.10.0's {GLOBAL_MGMT_VERSION:#x}"),
        ));
    }
    Ok(())
}

fn damaged(path: &Path, detail: String) -> ShmError {
    ShmError::Damaged {
        path: path.display().to_string(),
        detail,
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::panic)]

    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("sar-shm-access-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    /// The daemon creates a missing directory 2770, takes other users'
    /// access away from one it owns, and refuses a file; a client creates
    /// nothing.
    #[test]
    fn the_daemon_makes_and_fences_its_directory_and_a_client_creates_nothing() {
        let d = scratch("fence");
        let e = prepare(&d, Side::Client).unwrap_err();
        assert!(matches!(e, ShmError::NoRuntimeDir { .. }), "{e:?}");
        assert!(!d.exists());
        prepare(&d, Side::Daemon).unwrap();
        let mode = std::fs::metadata(&d).unwrap().mode() & 0o7777;
        assert_eq!(mode, RUNTIME_DIR_MODE, "{mode:o}");
        // Others' bits go, the set-group-ID bit stays.
        std::fs::set_permissions(&d, std::fs::Permissions::from_mode(0o2777)).unwrap();
        prepare(&d, Side::Daemon).unwrap();
        let mode = std::fs::metadata(&d).unwrap().mode() & 0o7777;
        assert_eq!(mode, 0o2770, "{mode:o}");
        prepare(&d, Side::Client).unwrap();
        let f = d.join("file");
        std::fs::write(&f, b"").unwrap();
        let e = prepare(&f, Side::Daemon).unwrap_err();
        assert!(e.to_string().contains("not a directory"), "{e}");
        let _ = std::fs::remove_dir_all(&d);
    }
}
