//! The access model (issues 25 and 35): where the daemon and its clients
//! meet, who may, and the checks made before iceoryx2 is called.
//!
//! Every iceoryx2 file of a daemon lives in its runtime directory
//! ([`DEFAULT_RUNTIME_DIR`], or `SAR_RUNTIME_DIR`: an absolute path):
//! under systemd `RuntimeDirectory=sar`, owned by the daemon's user and its
//! group `sar`, mode 3770 (set-group-ID, sticky). The daemon's user and the
//! members of the directory's group (the operators) read and command;
//! nobody else can enter the directory, so nobody else can read, command,
//! create or damage anything there. A member may watch and command, but
//! must not be able to stop the guard or corrupt what it shows:
//!
//! - The directory and iceoryx2's [`NODES_DIR`] are sticky: a member removes
//!   or renames none of the daemon's files; [`SERVICES_DIR`] and the
//!   daemon's node directory are the daemon's alone to write.
//! - The daemon's data segments are the group's to read only (the clients
//!   map them read-only: [`fence_own_files`]). The files a member must write
//!   to talk to the daemon (a service's dynamic configuration, a connection,
//!   an event's) it can truncate: the daemon then stops cleanly on the
//!   SIGBUS (`sar_loop::rt::install_bus_guard`).
//! - The daemon creates the directory when it is missing (mode 3770), refuses
//!   one that is not a directory or belongs to another user, takes the
//!   other users' access away when the mode gives them any, and writes a
//!   fresh management file in place of a damaged or foreign one.
//! - A client never creates it: a missing directory means no daemon runs;
//!   one it may not enter is refused at once, naming the user and the group.
//! - A client checks iceoryx2's management file before creating a node: a
//!   truncated or foreign one made iceoryx2 spin forever (issue 25).
//! - The daemon removes what dead clients left ([`sweep_half_made_nodes`]
//!   and iceoryx2's own cleaning, every second).
//!
//! The `unsafe` here: `libc` calls (user and group names, `faccessat`,
//! `getgroups`, `open` with `O_PATH`, `fstat`, `chmod`) on buffers owned
//! by the caller.
#![allow(unsafe_code)]

use crate::ShmError;
use std::ffi::CString;
use std::os::unix::ffi::OsStrExt;
use std::os::unix::fs::{FileTypeExt, MetadataExt, PermissionsExt};
use std::path::{Path, PathBuf};

/// The runtime directory when `SAR_RUNTIME_DIR` is not set (systemd's
/// `RuntimeDirectory=sar`).
pub const DEFAULT_RUNTIME_DIR: &str = "/run/sar";
/// The environment variable that names the runtime directory (the daemon and
/// its clients must agree; tests give each daemon its own).
pub const RUNTIME_DIR_ENV: &str = "SAR_RUNTIME_DIR";
/// The mode the daemon gives a runtime directory it creates (and every one
/// it starts in): the user's and the group's, set-group-ID, so that every
/// file in it (an operator's too) belongs to the directory's group, and
/// sticky, so that nobody but the daemon removes or renames another's file.
pub const RUNTIME_DIR_MODE: u32 = 0o3770;
/// How the name of iceoryx2's management segment in the runtime directory
/// ends (iceoryx2 0.10: `iox2_<hash>_node.0_10_0.global_mgmt`).
pub const GLOBAL_MGMT_SUFFIX: &str = ".global_mgmt";
/// The size of a healthy management segment, bytes (a version and a node
/// counter; checked by a test against the file iceoryx2 writes).
pub const GLOBAL_MGMT_SIZE: u64 = 16;

/// The first 8 bytes of a healthy management segment: iceoryx2's version
/// (0.10.0: major << 32 | minor << 16 | patch), little-endian.
pub const GLOBAL_MGMT_VERSION: u64 = 10 << 16;

/// The runtime directory: `SAR_RUNTIME_DIR` when set (an absolute path;
/// empty or relative is refused: an empty one used to fall back to the
/// production directory, and a relative one was taken from each process's
/// working directory, so that `sard` and `sarctl` disagreed); else
/// [`DEFAULT_RUNTIME_DIR`] when it exists (a daemon under systemd) or for
/// root; else, for a user without it (a developer's `sard --sim` and its
/// `sarctl`), `$XDG_RUNTIME_DIR/sar` when that is set; else
/// [`DEFAULT_RUNTIME_DIR`].
pub fn runtime_dir() -> Result<PathBuf, ShmError> {
    runtime_dir_from(
        std::env::var_os(RUNTIME_DIR_ENV).as_deref(),
        std::env::var_os("XDG_RUNTIME_DIR").as_deref(),
    )
}

/// [`runtime_dir`] from the values of `SAR_RUNTIME_DIR` and
/// `XDG_RUNTIME_DIR` (`None`: unset).
pub fn runtime_dir_from(
    sar: Option<&std::ffi::OsStr>,
    xdg: Option<&std::ffi::OsStr>,
) -> Result<PathBuf, ShmError> {
    if let Some(d) = sar {
        if d.is_empty() {
            return Err(ShmError::RuntimeDirEnv {
                detail: format!(
                    "{RUNTIME_DIR_ENV} is set but empty: give an absolute path, or unset it for the default ({DEFAULT_RUNTIME_DIR})"
                ),
            });
        }
        let path = PathBuf::from(d);
        if !path.is_absolute() {
            return Err(ShmError::RuntimeDirEnv {
                detail: format!(
                    "{RUNTIME_DIR_ENV}={} is a relative path (sard and sarctl would each take it from their own working directory): give an absolute path",
                    path.display()
                ),
            });
        }
        return Ok(path);
    }
    let default = PathBuf::from(DEFAULT_RUNTIME_DIR);
    if euid() == 0 || std::fs::symlink_metadata(&default).is_ok() {
        return Ok(default);
    }
    match xdg.filter(|d| !d.is_empty()) {
        Some(x) if Path::new(x).is_absolute() => Ok(PathBuf::from(x).join("sar")),
        _ => Ok(default),
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
///
/// The daemon also makes the directory sticky (a member may create files
/// in it, but never remove or rename another's: the daemon's files stay
/// the daemon's), makes iceoryx2's two subdirectories its own
/// ([`NODES_DIR`] sticky and open to the group's new nodes,
/// [`SERVICES_DIR`] readable only: the daemon alone creates services), and
/// writes a fresh management file in place of a damaged or foreign one
/// (a member could truncate it, or plant a FIFO under its name, and so keep
/// `sard` from starting).
pub fn prepare(dir: &Path, side: Side) -> Result<(), ShmError> {
    let meta = match std::fs::symlink_metadata(dir) {
        Ok(m) => m,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => match side {
            Side::Client => {
                return Err(ShmError::NoRuntimeDir {
                    dir: dir.display().to_string(),
                });
            }
            Side::Daemon => create_dir(dir)?,
        },
        Err(e) if e.kind() == std::io::ErrorKind::PermissionDenied => {
            return Err(denied(dir, None));
        }
        Err(e) => return Err(dir_error(dir, format!("cannot read it: {e}"))),
    };
    if !meta.file_type().is_dir() {
        return Err(dir_error(dir, "not a directory"));
    }
    if side == Side::Daemon {
        own_dir_mode(dir, &meta)?;
    }
    if may(dir, libc::R_OK | libc::W_OK | libc::X_OK).is_err() {
        return Err(denied(dir, Some(&meta)));
    }
    if side == Side::Daemon {
        own_subdir(dir, NODES_DIR, NODES_DIR_MODE)?;
        own_subdir(dir, SERVICES_DIR, SERVICES_DIR_MODE)?;
        ensure_mgmt(dir)?;
    }
    check_mgmt(dir)
}

/// The daemon makes the missing runtime directory `dir`, never open to
/// others, not even before its mode is set (a daemon making it at the same
/// moment is no error).
fn create_dir(dir: &Path) -> Result<std::fs::Metadata, ShmError> {
    use std::os::unix::fs::DirBuilderExt;
    match std::fs::DirBuilder::new().mode(0o770).create(dir) {
        Ok(()) => std::fs::set_permissions(dir, std::fs::Permissions::from_mode(RUNTIME_DIR_MODE))
            .map_err(|e| dir_error(dir, format!("cannot set its mode: {e}")))?,
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
        Err(e) => return Err(dir_error(dir, format!("cannot create it: {e}"))),
    }
    std::fs::symlink_metadata(dir).map_err(|e| dir_error(dir, format!("cannot read it: {e}")))
}

/// The daemon's runtime directory `dir` (read as `meta`): its own (else
/// refused, naming both users), other users keep nothing (the directory is
/// the fence), sticky and set-group-ID (changes logged).
fn own_dir_mode(dir: &Path, meta: &std::fs::Metadata) -> Result<(), ShmError> {
    let me = euid();
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
    let mode = meta.mode() & 0o7777;
    let wanted = (mode & 0o0770) | 0o3000;
    if wanted != mode {
        std::fs::set_permissions(dir, std::fs::Permissions::from_mode(wanted))
            .map_err(|e| dir_error(dir, format!("cannot set its mode {wanted:04o}: {e}")))?;
        let why = if mode & 0o007 != 0 {
            "took other users' access away"
        } else {
            "made it sticky and set-group-ID"
        };
        tracing::warn!("{}: {why} (mode {mode:04o} -> {wanted:04o})", dir.display());
    }
    Ok(())
}

/// iceoryx2's directory of the nodes in the runtime directory (its default
/// `global.node.directory`): every process makes its node there.
pub const NODES_DIR: &str = "nodes";
/// iceoryx2's directory of the services' static files (its default
/// `global.service.directory`): only the daemon creates services.
pub const SERVICES_DIR: &str = "services";
/// [`NODES_DIR`]'s mode: the group creates its nodes, sticky (nobody
/// removes another's), set-group-ID.
pub const NODES_DIR_MODE: u32 = 0o3770;
/// [`SERVICES_DIR`]'s mode: the group reads, only the daemon writes.
pub const SERVICES_DIR_MODE: u32 = 0o2750;
/// The mode of the daemon's own node directory (`nodes/ID`): the group
/// reads it, only the daemon writes.
pub const OWN_NODE_DIR_MODE: u32 = 0o2750;

/// Makes `dir/name` a directory of this process's user with `mode`: made
/// when missing; another user's entry there (a member's, made before the
/// daemon's start) is renamed aside (the daemon owns the sticky directory)
/// and a fresh one made.
fn own_subdir(dir: &Path, name: &str, mode: u32) -> Result<(), ShmError> {
    use std::os::unix::fs::DirBuilderExt;
    let path = dir.join(name);
    match std::fs::symlink_metadata(&path) {
        Ok(m) if m.file_type().is_dir() && m.uid() == euid() => {
            if m.mode() & 0o7777 != mode {
                std::fs::set_permissions(&path, std::fs::Permissions::from_mode(mode))
                    .map_err(|e| dir_error(dir, format!("cannot set the mode of {name}/: {e}")))?;
            }
            return Ok(());
        }
        Ok(m) => {
            let aside = dir.join(format!(
                ".{name}.foreign-{}-{}",
                std::process::id(),
                std::time::SystemTime::now()
                    .duration_since(std::time::UNIX_EPOCH)
                    .map_or(0, |d| d.as_nanos())
            ));
            std::fs::rename(&path, &aside).map_err(|e| {
                dir_error(
                    dir,
                    format!(
                        "{name} belongs to {} and cannot be moved aside: {e}",
                        user_name(m.uid())
                    ),
                )
            })?;
            tracing::warn!(
                "{}: {name} belonged to {} (mode {:04o}): moved aside to {}",
                dir.display(),
                user_name(m.uid()),
                m.mode() & 0o7777,
                aside.display()
            );
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => return Err(dir_error(dir, format!("cannot read {name}/: {e}"))),
    }
    match std::fs::DirBuilder::new().mode(0o700).create(&path) {
        Ok(()) => {}
        // Made meanwhile (another daemon starting at the same moment, which
        // then fails on the services): checked again below.
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
        Err(e) => return Err(dir_error(dir, format!("cannot create {name}/: {e}"))),
    }
    let m = std::fs::symlink_metadata(&path)
        .map_err(|e| dir_error(dir, format!("cannot read {name}/: {e}")))?;
    if !m.file_type().is_dir() || m.uid() != euid() {
        return Err(dir_error(
            dir,
            format!("{name} was replaced while sard made it"),
        ));
    }
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(mode))
        .map_err(|e| dir_error(dir, format!("cannot set the mode of {name}/: {e}")))
}

/// The name of iceoryx2 0.10's management file in the runtime directory
/// (a prefix, the hash of its type, `node`, the version: the same in every
/// directory; checked by a test against the file iceoryx2 writes).
pub const GLOBAL_MGMT_FILE: &str =
    "iox2_9204dd183d1c4d8e1ff592a30766ffa6765aa8b5_node.0_10_0.global_mgmt";
/// The management file's mode: every node of the group counts in it.
pub const GLOBAL_MGMT_MODE: u32 = 0o660;

/// The daemon's management file: kept when it is a healthy regular file of
/// the daemon's user; else (damaged, a FIFO, a link, another user's, or
/// missing) a fresh one is written beside it and renamed over it (atomic:
/// no moment without a healthy file), and a damaged one is named in the
/// log. Its content is iceoryx2's own: the version, then a node counter
/// (0; node ids also carry the process id and the time).
fn ensure_mgmt(dir: &Path) -> Result<(), ShmError> {
    use std::io::Write;
    use std::os::unix::fs::OpenOptionsExt;
    let path = dir.join(GLOBAL_MGMT_FILE);
    let problem = match std::fs::symlink_metadata(&path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
        Err(e) => Some(format!("cannot read it: {e}")),
        Ok(m) if m.uid() != euid() => Some(format!(
            "owned by {}, not by sard's user {}",
            user_name(m.uid()),
            user_name(euid())
        )),
        Ok(_) => match check_mgmt_file(&path) {
            Ok(()) => return Ok(()),
            Err(ShmError::Damaged { detail, .. }) => Some(detail),
            Err(e) => Some(e.to_string()),
        },
    };
    let fresh = dir.join(format!(".{GLOBAL_MGMT_FILE}.{}", std::process::id()));
    let _ = std::fs::remove_file(&fresh);
    let write = || -> std::io::Result<()> {
        let mut f = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .mode(0o600)
            .custom_flags(libc::O_NOFOLLOW)
            .open(&fresh)?;
        let mut bytes = [0u8; GLOBAL_MGMT_SIZE as usize];
        bytes[..8].copy_from_slice(&GLOBAL_MGMT_VERSION.to_le_bytes());
        f.write_all(&bytes)?;
        f.set_permissions(std::fs::Permissions::from_mode(GLOBAL_MGMT_MODE))?;
        std::fs::rename(&fresh, &path)
    };
    if let Err(e) = write() {
        let _ = std::fs::remove_file(&fresh);
        return Err(damaged(
            &path,
            format!(
                "{}; sard cannot write a fresh one: {e}",
                problem.unwrap_or_else(|| "missing".to_owned())
            ),
        ));
    }
    if let Some(p) = problem {
        tracing::warn!(
            "the shared-memory management file {} was damaged ({p}): replaced by a fresh one",
            path.display()
        );
    }
    Ok(())
}

/// Takes the other users' access away from this process's own iceoryx2
/// files in the runtime directory `dir`, and the group's write access from
/// its data segments (`.data`: the other side maps them read-only, so a
/// member can never truncate them under the process). iceoryx2
/// (`dev_permissions`) makes its files 0666 and its directories 0777; the
/// directory already keeps others out, this keeps a file that leaves it (a
/// hard link made elsewhere by a member) closed to them too.
///
/// Which files: the ones this process maps or holds open in `dir` (from
/// `/proc/self/maps` and `/proc/self/fd`), its bound sockets there
/// (`/proc/self/net/unix`, matched with its open sockets), and the entries
/// of `own_dirs` (directories only this process writes: its node's
/// directory, the daemon's services) and `own_files` (its node's monitor
/// files). So the work of a pass is bounded by what the process itself has
/// made, never by what others put in the directory (a member's 4096 junk
/// files stopped the old directory walk before the daemon's newest files).
///
/// Each file is opened without following a link (`O_PATH | O_NOFOLLOW`),
/// checked on the open file (this process's user, the directory's group,
/// not a link) and changed through that descriptor: a link swapped in
/// after a check is never followed. Files still being made (iceoryx2's
/// write-only initial modes: no other users' bits yet) are left alone.
/// Returns how many it changed. The daemon calls it when it has made its
/// services and then on its maintenance thread every
/// [`crate::REAP_PERIOD`], a client after making its ports.
pub fn fence_own_files(dir: &Path, own_dirs: &[PathBuf], own_files: &[PathBuf]) -> usize {
    let Ok(group) = std::fs::metadata(dir).map(|m| m.gid()) else {
        return 0;
    };
    let mut candidates = own_open_files(dir);
    candidates.extend(own_files.iter().cloned());
    for d in own_dirs {
        candidates.push(d.clone());
        if let Ok(entries) = std::fs::read_dir(d) {
            candidates.extend(entries.flatten().take(FENCE_LIMIT).map(|e| e.path()));
        }
    }
    candidates.sort();
    candidates.dedup();
    candidates.iter().filter(|p| fence_path(p, group)).count()
}

/// Fences one path (see [`fence_own_files`]): whether its mode changed.
fn fence_path(path: &Path, group: u32) -> bool {
    let Ok(c) = CString::new(path.as_os_str().as_bytes()) else {
        return false;
    };
    // SAFETY: a valid NUL-terminated path; the descriptor is closed below.
    let fd = unsafe {
        libc::open(
            c.as_ptr(),
            libc::O_PATH | libc::O_NOFOLLOW | libc::O_CLOEXEC,
        )
    };
    if fd < 0 {
        return false;
    }
    // SAFETY: a plain C struct; all-zero is a valid value, written by fstat.
    let mut st: libc::stat = unsafe { std::mem::zeroed() };
    // SAFETY: `fd` is open; `st` is a valid buffer.
    let ok = unsafe { libc::fstat(fd, &mut st) } == 0;
    let mut changed = false;
    if ok && st.st_uid == euid() && st.st_gid == group {
        let kind = st.st_mode & libc::S_IFMT;
        let mode = st.st_mode & 0o7777;
        let data = kind == libc::S_IFREG && path.as_os_str().as_bytes().ends_with(b".data");
        let mut wanted = mode;
        if mode & 0o007 != 0 {
            wanted &= 0o7770;
            if data {
                wanted &= !0o020;
            }
        } else if data && mode & 0o020 != 0 {
            wanted &= !0o020;
        }
        if kind != libc::S_IFLNK && wanted != mode {
            // The open file itself, through its descriptor (an `O_PATH`
            // descriptor takes no fchmod; its /proc link names the inode).
            if let Ok(proc) = CString::new(format!("/proc/self/fd/{fd}")) {
                // SAFETY: a valid NUL-terminated path.
                changed = unsafe { libc::chmod(proc.as_ptr(), wanted) } == 0;
            }
        }
    }
    // SAFETY: `fd` was opened above and is closed once.
    unsafe { libc::close(fd) };
    changed
}

/// The files this process maps or holds open under `dir`, and the unix
/// sockets it has bound there.
fn own_open_files(dir: &Path) -> Vec<PathBuf> {
    let prefix = {
        let mut p = dir.as_os_str().as_bytes().to_vec();
        p.push(b'/');
        p
    };
    let under = |p: &[u8]| p.starts_with(&prefix);
    let mut out = Vec::new();
    if let Ok(maps) = std::fs::read("/proc/self/maps") {
        for line in maps.split(|b| *b == b'\n') {
            // address perms offset dev inode path
            let Some(path) = line
                .iter()
                .position(|b| *b == b'/')
                .and_then(|start| line.get(start..))
            else {
                continue;
            };
            if under(path) && !path.ends_with(b" (deleted)") {
                out.push(PathBuf::from(std::ffi::OsStr::from_bytes(path)));
            }
        }
    }
    let mut sockets = Vec::new();
    if let Ok(fds) = std::fs::read_dir("/proc/self/fd") {
        for e in fds.flatten() {
            let Ok(target) = std::fs::read_link(e.path()) else {
                continue;
            };
            let t = target.as_os_str().as_bytes();
            if under(t) {
                out.push(target);
            } else if let Some(inode) = t
                .strip_prefix(b"socket:[")
                .and_then(|s| s.strip_suffix(b"]"))
            {
                sockets.push(inode.to_vec());
            }
        }
    }
    if !sockets.is_empty()
        && let Ok(unix) = std::fs::read("/proc/self/net/unix")
    {
        // Num RefCount Protocol Flags Type St Inode Path
        for line in unix.split(|b| *b == b'\n').skip(1) {
            let fields: Vec<&[u8]> = line
                .split(|b| *b == b' ')
                .filter(|f| !f.is_empty())
                .collect();
            if let (Some(inode), Some(path)) = (fields.get(6), fields.get(7))
                && under(path)
                && sockets.iter().any(|s| s.as_slice() == *inode)
            {
                out.push(PathBuf::from(std::ffi::OsStr::from_bytes(path)));
            }
        }
    }
    out
}

/// Entries of one of a process's own directories a fence looks at, at most.
pub const FENCE_LIMIT: usize = 4096;

/// How old a half-made node must be before the daemon removes it
/// ([`sweep_half_made_nodes`]): a node is made in well under a millisecond;
/// only a process killed while it made its node leaves one behind.
pub const HALF_MADE_NODE_AGE: std::time::Duration = std::time::Duration::from_secs(5);

/// Removes the nodes that a process killed while making its node left in
/// [`NODES_DIR`] of the runtime directory `dir`, which iceoryx2 never
/// cleans (it lists nodes by their monitor files, and takes a monitor whose
/// making was cut for one still starting): a node directory without any
/// monitor file, and the monitor files whose context file still has its
/// initial write-only mode, once they are [`HALF_MADE_NODE_AGE`] old (by
/// their last change). Never a node with a finished monitor (alive or
/// dead: iceoryx2's own cleaning is for those). Returns how many nodes it
/// removed. The daemon's maintenance thread calls it every pass (the
/// directory is the daemon's and sticky: it may remove anything in it).
pub fn sweep_half_made_nodes(dir: &Path) -> usize {
    let nodes = dir.join(NODES_DIR);
    let (dirs, monitors) = node_entries(&nodes);
    let mut removed = sweep_half_made_monitors(&nodes, &monitors);
    // A tag (a node's record of a port or a service, made before the port's
    // resources) still in its initial mode: its maker died making it; it
    // stopped iceoryx2's cleaning of that dead node for good (the node
    // stayed, with every file it had).
    for id in &dirs {
        let Ok(tags) = std::fs::read_dir(nodes.join(id)) else {
            continue;
        };
        for t in tags.flatten().take(FENCE_LIMIT) {
            let p = t.path();
            let half_made = std::fs::symlink_metadata(&p).is_ok_and(|m| {
                m.file_type().is_file() && matches!(m.mode() & 0o777, 0o600 | 0o200)
            });
            if half_made && is_old(&p) && std::fs::remove_file(&p).is_ok() {
                removed += 1;
            }
        }
    }
    removed += sweep_half_made_ports(dir);
    for id in dirs.iter().filter(|id| !monitors.contains(*id)) {
        let path = nodes.join(id);
        if std::fs::symlink_metadata(&path).is_ok_and(|m| m.file_type().is_dir())
            && is_old(&path)
            && std::fs::remove_dir_all(&path).is_ok()
        {
            removed += 1;
        }
    }
    removed
}

/// The node ids of [`NODES_DIR`]'s entries: those with a directory
/// (`ID/`), and those with a monitor file (`iox2_ID.node_monitor*`).
fn node_entries(
    nodes: &Path,
) -> (
    std::collections::BTreeSet<String>,
    std::collections::BTreeSet<String>,
) {
    let mut dirs = std::collections::BTreeSet::new();
    let mut monitors = std::collections::BTreeSet::new();
    let digits = |b: &[u8]| !b.is_empty() && b.iter().all(u8::is_ascii_digit);
    for e in std::fs::read_dir(nodes).into_iter().flatten().flatten() {
        let name = e.file_name();
        let name = name.as_bytes();
        if let Some(rest) = name.strip_prefix(b"iox2_") {
            if let Some(id) = rest
                .iter()
                .position(|b| *b == b'.')
                .and_then(|dot| rest.get(..dot))
                .filter(|id| digits(id))
            {
                monitors.insert(String::from_utf8_lossy(id).into_owned());
            }
        } else if digits(name) {
            dirs.insert(String::from_utf8_lossy(name).into_owned());
        }
    }
    (dirs, monitors)
}

/// Whether `path` last changed (its contents or its inode) at least
/// [`HALF_MADE_NODE_AGE`] ago.
fn is_old(path: &Path) -> bool {
    std::fs::symlink_metadata(path).is_ok_and(|m| {
        let secs = m.ctime().max(m.mtime()).max(0).unsigned_abs();
        (std::time::UNIX_EPOCH + std::time::Duration::new(secs, 0))
            .elapsed()
            .is_ok_and(|age| age >= HALF_MADE_NODE_AGE)
    })
}

/// Removes the monitor files (and the directory) of the nodes in `nodes`
/// whose making or ending was cut: the context file still write-only (a
/// process killed while it made its node), or the state file gone (one
/// killed while it let go of it removes that one first; iceoryx2 lists
/// nodes by it). Returns how many.
fn sweep_half_made_monitors(nodes: &Path, ids: &std::collections::BTreeSet<String>) -> usize {
    let file = |id: &str, kind: &str| nodes.join(format!("iox2_{id}.{kind}"));
    let mut removed = 0;
    for id in ids {
        let context = file(id, "node_monitor_context");
        let starting = std::fs::symlink_metadata(&context)
            .is_ok_and(|m| m.file_type().is_file() && m.mode() & 0o777 == 0o200);
        let ending = std::fs::symlink_metadata(file(id, "node_monitor"))
            .is_err_and(|e| e.kind() == std::io::ErrorKind::NotFound);
        let made = if context.exists() {
            context
        } else {
            file(id, "node_monitor_owner_lock")
        };
        if (starting || ending) && is_old(&made) {
            for kind in [
                "node_monitor",
                "node_monitor_owner_lock",
                "node_monitor_context",
            ] {
                let _ = std::fs::remove_file(file(id, kind));
            }
            let _ = std::fs::remove_dir_all(nodes.join(id));
            removed += 1;
        }
    }
    removed
}

/// The files in the runtime directory `dir` itself that a process killed
/// while it made a port left behind: a file still in iceoryx2's initial
/// write-only modes (0200, 0600: never a finished file's, which the group
/// reads), and a unix socket (an event's listener) nobody listens on, once
/// [`HALF_MADE_NODE_AGE`] old. Returns how many it removed.
fn sweep_half_made_ports(dir: &Path) -> usize {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return 0;
    };
    let mut removed = 0;
    for e in entries.flatten() {
        let path = e.path();
        if !path
            .file_name()
            .is_some_and(|n| n.as_bytes().starts_with(b"iox2_"))
        {
            continue;
        }
        let Ok(m) = std::fs::symlink_metadata(&path) else {
            continue;
        };
        if !is_old(&path) {
            continue;
        }
        let name = path
            .file_name()
            .map(|n| n.as_bytes().to_vec())
            .unwrap_or_default();
        let stale = if m.file_type().is_file() {
            matches!(m.mode() & 0o777, 0o200 | 0o600) || listener_gone(dir, &name)
        } else if m.file_type().is_socket() {
            nobody_listens(&path)
        } else {
            false
        };
        if stale && std::fs::remove_file(&path).is_ok() {
            removed += 1;
        }
    }
    removed
}

/// Whether `name` is an event listener's storage
/// (`iox2_HASH_PORT.event_mgmt`) whose socket (`iox2_PORT.event`) is gone:
/// its listener died while it let go of its port (the socket removed, the
/// storage not yet).
fn listener_gone(dir: &Path, name: &[u8]) -> bool {
    let Some(stem) = name.strip_suffix(b".event_mgmt") else {
        return false;
    };
    let Some(port) = stem
        .iter()
        .rposition(|b| *b == b'_')
        .and_then(|i| stem.get(i + 1..))
        .filter(|p| !p.is_empty() && p.iter().all(u8::is_ascii_digit))
    else {
        return false;
    };
    let mut socket = b"iox2_".to_vec();
    socket.extend_from_slice(port);
    socket.extend_from_slice(b".event");
    matches!(
        std::fs::symlink_metadata(dir.join(std::ffi::OsStr::from_bytes(&socket))),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound
    )
}

/// Whether nobody is bound to the datagram socket at `path` (connecting to
/// it is refused). Sends nothing.
fn nobody_listens(path: &Path) -> bool {
    let Ok(socket) = std::os::unix::net::UnixDatagram::unbound() else {
        return false;
    };
    matches!(
        socket.connect(path).map_err(|e| e.kind()),
        Err(std::io::ErrorKind::ConnectionRefused)
    )
}

/// This process's node files in the runtime directory `dir` for the node
/// `node_id` (iceoryx2's `UniqueNodeId::value`): its directory (the
/// daemon's is made the group's to read only) and its monitor files.
pub fn node_paths(dir: &Path, node_id: u128) -> (PathBuf, Vec<PathBuf>) {
    let nodes = dir.join(NODES_DIR);
    let files = [
        "node_monitor",
        "node_monitor_context",
        "node_monitor_owner_lock",
    ]
    .iter()
    .map(|s| nodes.join(format!("iox2_{node_id}.{s}")))
    .collect();
    (nodes.join(node_id.to_string()), files)
}

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
/// forever on an empty one and faults on a short one. Only its one name
/// ([`GLOBAL_MGMT_FILE`]) is looked at: no listing, so that no number of
/// other files in the directory delays the check.
pub(crate) fn check_mgmt(dir: &Path) -> Result<(), ShmError> {
    check_mgmt_file(&dir.join(GLOBAL_MGMT_FILE))
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

    /// The daemon creates a missing directory 3770, takes other users'
    /// access away from one it owns, makes iceoryx2's subdirectories and
    /// management file its own, and refuses a file; a client creates
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
        // Others' bits go, the set-group-ID and sticky bits come back.
        std::fs::set_permissions(&d, std::fs::Permissions::from_mode(0o0777)).unwrap();
        prepare(&d, Side::Daemon).unwrap();
        let mode = std::fs::metadata(&d).unwrap().mode() & 0o7777;
        assert_eq!(mode, 0o3770, "{mode:o}");
        // iceoryx2's subdirectories are the daemon's, and a healthy
        // management file of the daemon is there before iceoryx2 runs.
        let mode = |p: &Path| std::fs::metadata(p).unwrap().mode() & 0o7777;
        assert_eq!(mode(&d.join(NODES_DIR)), NODES_DIR_MODE);
        assert_eq!(mode(&d.join(SERVICES_DIR)), SERVICES_DIR_MODE);
        check_mgmt(&d).unwrap();
        assert_eq!(mode(&d.join(GLOBAL_MGMT_FILE)), GLOBAL_MGMT_MODE);
        prepare(&d, Side::Client).unwrap();
        let f = d.join("file");
        std::fs::write(&f, b"").unwrap();
        let e = prepare(&f, Side::Daemon).unwrap_err();
        assert!(e.to_string().contains("not a directory"), "{e}");
        let _ = std::fs::remove_dir_all(&d);
    }

    /// Finding 11: an empty `SAR_RUNTIME_DIR` was taken as unset (the
    /// production directory), a relative one from each process's working
    /// directory; both are refused in one line.
    #[test]
    fn an_empty_or_relative_runtime_dir_is_refused() {
        use std::ffi::OsStr;
        let e = runtime_dir_from(Some(OsStr::new("")), None).unwrap_err();
        assert_eq!(
            e.to_string(),
            "SAR_RUNTIME_DIR is set but empty: give an absolute path, or unset it for the default (/run/sar)"
        );
        for rel in ["run", "./run", "../x/run"] {
            let e = runtime_dir_from(Some(OsStr::new(rel)), None).unwrap_err();
            assert!(
                e.to_string()
                    .starts_with(&format!("SAR_RUNTIME_DIR={rel} is a relative path")),
                "{e}"
            );
        }
        assert_eq!(
            runtime_dir_from(Some(OsStr::new("/tmp/x")), None).unwrap(),
            PathBuf::from("/tmp/x")
        );
    }

    /// Finding 13: the fence followed a symbolic link swapped in after its
    /// check, and a member's junk files (4096 of them) stopped the walk
    /// before the daemon's newest files. Now it fences exactly the files
    /// this process maps or holds, and its own directories; a link is
    /// never followed; junk costs nothing.
    #[test]
    fn the_fence_changes_only_own_files_never_through_a_link_whatever_the_junk() {
        use std::os::unix::fs::OpenOptionsExt;
        let d = scratch("fence_own");
        prepare(&d, Side::Daemon).unwrap();
        // 5000 junk files (a member's: here this user's, but not open).
        for i in 0..5000 {
            std::fs::OpenOptions::new()
                .write(true)
                .create(true)
                .truncate(true)
                .mode(0o666)
                .open(d.join(format!("iox2_junk_{i:05}")))
                .unwrap()
                .set_permissions(std::fs::Permissions::from_mode(0o666))
                .unwrap();
        }
        // A data segment and another file this process holds open, made
        // 0666 as iceoryx2 makes them.
        let data = d.join("iox2_zzz_own.data");
        let other = d.join("iox2_zzz_own.dynamic");
        let held: Vec<std::fs::File> = [&data, &other]
            .iter()
            .map(|p| {
                let f = std::fs::OpenOptions::new()
                    .read(true)
                    .write(true)
                    .create(true)
                    .truncate(true)
                    .open(p)
                    .unwrap();
                f.set_permissions(std::fs::Permissions::from_mode(0o666))
                    .unwrap();
                f
            })
            .collect();
        // A link to a file outside, in a directory this process fences as
        // its own: never followed.
        let outside = scratch("fence_outside");
        std::fs::create_dir_all(&outside).unwrap();
        let target = outside.join("target");
        std::fs::write(&target, b"").unwrap();
        std::fs::set_permissions(&target, std::fs::Permissions::from_mode(0o666)).unwrap();
        let own = d.join(NODES_DIR).join("1234");
        std::fs::create_dir_all(&own).unwrap();
        std::os::unix::fs::symlink(&target, own.join("iox2_link.port_tag")).unwrap();
        let changed = fence_own_files(&d, std::slice::from_ref(&own), &[]);
        let mode = |p: &Path| std::fs::metadata(p).unwrap().mode() & 0o7777;
        assert_eq!(mode(&data), 0o640, "a data segment: the group reads only");
        assert_eq!(mode(&other), 0o660);
        assert_eq!(mode(&target), 0o666, "followed a link");
        assert_eq!(mode(&d.join("iox2_junk_04999")), 0o666, "walked the junk");
        assert!(changed >= 2, "{changed}");
        drop(held);
        let _ = std::fs::remove_dir_all(&d);
        let _ = std::fs::remove_dir_all(&outside);
    }
}
