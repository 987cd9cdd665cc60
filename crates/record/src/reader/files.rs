//! Files: opened only when regular, read whole, and the bound on what a
//! reader retains of a file ([`retained_limit`]).

use super::error::ReadError;
use std::path::Path;

/// What a reader may hold of schemas, channels and metadata for a file
/// (or bytes) of `file_bytes`: [`RETAINED_PER_FILE_BYTE`] times its length
/// plus [`RETAINED_BASE_BYTES`]. With one chunk's buffer (at most
/// [`MAX_CHUNK_BYTES`]) and its messages, this bounds a reader's memory by
/// the file's size and a constant.
pub fn retained_limit(file_bytes: u64) -> u64 {
    file_bytes
        .saturating_mul(RETAINED_PER_FILE_BYTE)
        .saturating_add(RETAINED_BASE_BYTES)
}

/// Bytes a reader may hold per byte of its file ([`retained_limit`]): a
/// record's strings cost their length and a fixed allowance, a compressed
/// chunk may hold a few times its length of them.
pub const RETAINED_PER_FILE_BYTE: u64 = 8;

/// Bytes a reader may hold whatever its file's length ([`retained_limit`]).
pub const RETAINED_BASE_BYTES: u64 = 16 * 1024 * 1024;

/// Opens `path` for reading if it is a regular file; anything else (a
/// FIFO, which would block until a writer comes; a device; a directory) is
/// refused at once, before it is opened.
pub fn open_regular(path: &Path) -> Result<std::fs::File, ReadError> {
    use std::os::unix::fs::FileTypeExt;
    let io = |source| ReadError::Io {
        path: path.to_path_buf(),
        source,
    };
    let kind = std::fs::metadata(path).map_err(io)?.file_type();
    let not = |kind| {
        Err(ReadError::NotRegular {
            path: path.to_path_buf(),
            kind,
        })
    };
    if kind.is_fifo() {
        return not("a FIFO");
    }
    if kind.is_char_device() {
        return not("a character device");
    }
    if kind.is_block_device() {
        return not("a block device");
    }
    if kind.is_socket() {
        return not("a socket");
    }
    if kind.is_dir() {
        return not("a directory");
    }
    if !kind.is_file() {
        return not("not a file");
    }
    std::fs::File::open(path).map_err(io)
}

/// Reads a whole file into memory (a regular file only: [`open_regular`]).
pub fn read_file(path: &Path) -> Result<Vec<u8>, ReadError> {
    use std::io::Read;
    let mut bytes = Vec::new();
    open_regular(path)?
        .read_to_end(&mut bytes)
        .map_err(|source| ReadError::Io {
            path: path.to_path_buf(),
            source,
        })?;
    Ok(bytes)
}
