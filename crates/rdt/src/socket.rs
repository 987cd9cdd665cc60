//! The driver's system calls on its UDP socket, the one place of this crate
//! with `unsafe` (plain libc calls on a descriptor the socket owns):
//!
//! - [`receive_batch`]: one `recvmmsg(MSG_DONTWAIT)` of at most [`BATCH`]
//!   datagrams into a fixed [`Batch`], each with the kernel's receive time
//!   (`SO_TIMESTAMPNS`, `CLOCK_REALTIME`); never blocks, never allocates.
//! - [`size_receive_buffer`]: asks `SO_RCVBUF` and reads back what the
//!   kernel granted; [`enable_timestamps`]: `SO_TIMESTAMPNS` on.
//! - [`wait_readable`]: `ppoll` on the socket, bounded by its timeout (for
//!   `wait` only, never on the loop's path).
//! - [`realtime_ns`]: `CLOCK_REALTIME`, the time base of the kernel's stamps.
#![allow(unsafe_code)]

use crate::codec::RESPONSE_LEN;
use std::io;
use std::net::UdpSocket;
use std::os::fd::AsRawFd;

/// Datagrams one `recvmmsg` reads at most.
pub const BATCH: usize = 32;
/// One byte more than a response: a longer datagram shows as such.
pub const DATAGRAM_BYTES: usize = RESPONSE_LEN + 1;
/// Room for one `SCM_TIMESTAMPNS` control message (`CMSG_SPACE` of a
/// timespec is 32 bytes on 64-bit Linux; twice that, in u64 for alignment).
const CONTROL_WORDS: usize = 8;

/// The buffers of one batch, and what the last [`receive_batch`] put in them.
#[derive(Debug)]
pub struct Batch {
    data: [[u8; DATAGRAM_BYTES]; BATCH],
    control: [[u64; CONTROL_WORDS]; BATCH],
    /// Bytes of each datagram received (at most [`DATAGRAM_BYTES`]).
    lens: [usize; BATCH],
    /// The kernel's receive time of each, `CLOCK_REALTIME` ns (`None`: no
    /// stamp came with it).
    stamps_ns: [Option<u64>; BATCH],
}

impl Default for Batch {
    fn default() -> Self {
        Self {
            data: [[0; DATAGRAM_BYTES]; BATCH],
            control: [[0; CONTROL_WORDS]; BATCH],
            lens: [0; BATCH],
            stamps_ns: [None; BATCH],
        }
    }
}

impl Batch {
    /// Datagram `i` of the last batch (its bytes) and its kernel stamp.
    pub fn datagram(&self, i: usize) -> (&[u8], Option<u64>) {
        let bytes = self
            .data
            .get(i)
            .zip(self.lens.get(i))
            .and_then(|(d, &n)| d.get(..n))
            .unwrap_or(&[]);
        (bytes, self.stamps_ns.get(i).copied().flatten())
    }
}

fn check(rc: libc::c_int) -> io::Result<libc::c_int> {
    if rc < 0 {
        Err(io::Error::last_os_error())
    } else {
        Ok(rc)
    }
}

fn timespec_ns(ts: &libc::timespec) -> Option<u64> {
    Some(
        u64::try_from(ts.tv_sec)
            .ok()?
            .saturating_mul(1_000_000_000)
            .saturating_add(u64::try_from(ts.tv_nsec).ok()?),
    )
}

/// Reads at most [`BATCH`] datagrams without waiting: how many (0 when none
/// was waiting). Fewer than [`BATCH`] means the socket was found empty (or
/// an error is pending, reported by the next call).
pub fn receive_batch(socket: &UdpSocket, batch: &mut Batch) -> io::Result<usize> {
    // SAFETY: zeroed iovec, msghdr and mmsghdr are valid (null pointers,
    // zero lengths) before they are filled below.
    let mut iovecs: [libc::iovec; BATCH] = unsafe { std::mem::zeroed() };
    let mut headers: [libc::mmsghdr; BATCH] = unsafe { std::mem::zeroed() };
    for (((iov, header), data), control) in iovecs
        .iter_mut()
        .zip(headers.iter_mut())
        .zip(batch.data.iter_mut())
        .zip(batch.control.iter_mut())
    {
        iov.iov_base = data.as_mut_ptr().cast();
        iov.iov_len = DATAGRAM_BYTES;
        header.msg_hdr.msg_iov = std::ptr::from_mut(iov);
        header.msg_hdr.msg_iovlen = 1;
        header.msg_hdr.msg_control = control.as_mut_ptr().cast();
        header.msg_hdr.msg_controllen = std::mem::size_of_val(control) as _;
    }
    // SAFETY: every header points at an iovec and a control buffer of this
    // function's or `batch`'s, alive and unaliased for the call; MSG_DONTWAIT
    // makes it return at once.
    let rc = unsafe {
        libc::recvmmsg(
            socket.as_raw_fd(),
            headers.as_mut_ptr(),
            BATCH as libc::c_uint,
            libc::MSG_DONTWAIT,
            std::ptr::null_mut(),
        )
    };
    let count = match check(rc) {
        Ok(n) => usize::try_from(n).unwrap_or(0).min(BATCH),
        Err(e) if e.kind() == io::ErrorKind::WouldBlock => 0,
        Err(e) => return Err(e),
    };
    for (i, header) in headers.iter().enumerate().take(count) {
        if let Some(len) = batch.lens.get_mut(i) {
            *len = usize::try_from(header.msg_len)
                .unwrap_or(0)
                .min(DATAGRAM_BYTES);
        }
        if let Some(stamp) = batch.stamps_ns.get_mut(i) {
            *stamp = kernel_stamp_ns(&header.msg_hdr);
        }
    }
    Ok(count)
}

/// The `SCM_TIMESTAMPNS` of a received message, ns of `CLOCK_REALTIME`.
fn kernel_stamp_ns(msg: &libc::msghdr) -> Option<u64> {
    // SAFETY: `msg` was filled by recvmmsg; the CMSG macros walk its
    // control buffer within `msg_controllen`; the payload is read unaligned.
    unsafe {
        let mut cmsg = libc::CMSG_FIRSTHDR(msg);
        while !cmsg.is_null() {
            if (*cmsg).cmsg_level == libc::SOL_SOCKET && (*cmsg).cmsg_type == libc::SCM_TIMESTAMPNS
            {
                let ts: libc::timespec =
                    std::ptr::read_unaligned(libc::CMSG_DATA(cmsg).cast::<libc::timespec>());
                return timespec_ns(&ts);
            }
            cmsg = libc::CMSG_NXTHDR(msg, cmsg);
        }
    }
    None
}

fn set_int(socket: &UdpSocket, name: libc::c_int, value: libc::c_int) -> io::Result<()> {
    // SAFETY: a c_int option value, its size given.
    let rc = unsafe {
        libc::setsockopt(
            socket.as_raw_fd(),
            libc::SOL_SOCKET,
            name,
            std::ptr::from_ref(&value).cast(),
            std::mem::size_of::<libc::c_int>() as libc::socklen_t,
        )
    };
    check(rc).map(|_| ())
}

/// Asks for a receive buffer of `bytes` (the kernel doubles the request for
/// its bookkeeping, and caps it at `net.core.rmem_max`): what it granted,
/// bytes, as `getsockopt(SO_RCVBUF)` reads it back.
pub fn size_receive_buffer(socket: &UdpSocket, bytes: usize) -> io::Result<usize> {
    set_int(
        socket,
        libc::SO_RCVBUF,
        libc::c_int::try_from(bytes).unwrap_or(libc::c_int::MAX),
    )?;
    let mut granted: libc::c_int = 0;
    let mut len = std::mem::size_of::<libc::c_int>() as libc::socklen_t;
    // SAFETY: a c_int out-parameter and its size.
    let rc = unsafe {
        libc::getsockopt(
            socket.as_raw_fd(),
            libc::SOL_SOCKET,
            libc::SO_RCVBUF,
            std::ptr::from_mut(&mut granted).cast(),
            &mut len,
        )
    };
    check(rc)?;
    Ok(usize::try_from(granted).unwrap_or(0))
}

/// Turns on the kernel's receive time of each datagram (`SO_TIMESTAMPNS`).
pub fn enable_timestamps(socket: &UdpSocket) -> io::Result<()> {
    set_int(socket, libc::SO_TIMESTAMPNS, 1)
}

/// Waits at most `timeout_ns` for the socket to be readable (a datagram or
/// an error waiting). Interrupted by a signal: returns early, as a timeout.
pub fn wait_readable(socket: &UdpSocket, timeout_ns: u64) -> io::Result<()> {
    let mut fd = libc::pollfd {
        fd: socket.as_raw_fd(),
        events: libc::POLLIN,
        revents: 0,
    };
    let timeout = libc::timespec {
        tv_sec: libc::time_t::try_from(timeout_ns / 1_000_000_000).unwrap_or(libc::time_t::MAX),
        tv_nsec: libc::c_long::try_from(timeout_ns % 1_000_000_000).unwrap_or(0),
    };
    // SAFETY: one pollfd and a timespec, both alive for the call.
    let rc = unsafe { libc::ppoll(&mut fd, 1, &timeout, std::ptr::null()) };
    match check(rc) {
        Ok(_) => Ok(()),
        Err(e) if e.kind() == io::ErrorKind::Interrupted => Ok(()),
        Err(e) => Err(e),
    }
}

/// `CLOCK_REALTIME`, ns (the kernel's receive stamps' time base), or `None`
/// when it cannot be read.
pub fn realtime_ns() -> Option<u64> {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: a valid, writable timespec.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_REALTIME, &mut ts) };
    if rc != 0 {
        return None;
    }
    timespec_ns(&ts)
}
