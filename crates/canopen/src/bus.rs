//! A deterministic in-memory CAN bus for tests: the host's end ([`MemCan`],
//! an `embedded_can::nb::Can`) and simulated drives on the other. A frame the
//! host sends reaches every drive at once (their replies are queued for the
//! host in order); [`MemBus::tick`] lets the drives' time pass (heartbeats,
//! watchdogs), as does every receive of the host once the clock has moved.
//! Nothing runs on its own: a test steps the bus by hand, on the same
//! simulated clock as the host. Error frames and bus-off are injected.

use crate::frame::RawFrame;
use crate::slave::SimCia402Drive;
use sar_hal::SimClock;
use std::cell::RefCell;
use std::collections::VecDeque;
use std::rc::Rc;

/// Frames queued for the host beyond this are dropped (an overrun).
const HOST_QUEUE: usize = 1024;
/// Frames kept in the log of what the host sent.
const LOG: usize = 65_536;

/// What the in-memory controller reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum MemBusError {
    /// The controller is bus-off: nothing is sent or received.
    #[error("bus-off")]
    BusOff,
    /// An error frame of this kind was seen.
    #[error("error frame: {0:?}")]
    ErrorFrame(embedded_can::ErrorKind),
    /// Frames for the host were lost (queue full).
    #[error("receive overrun")]
    Overrun,
}

impl embedded_can::Error for MemBusError {
    fn kind(&self) -> embedded_can::ErrorKind {
        match self {
            Self::BusOff => embedded_can::ErrorKind::Other,
            Self::ErrorFrame(kind) => *kind,
            Self::Overrun => embedded_can::ErrorKind::Overrun,
        }
    }
}

#[derive(Debug)]
struct Inner {
    clock: SimClock,
    drives: Vec<SimCia402Drive>,
    to_host: VecDeque<RawFrame>,
    errors: VecDeque<MemBusError>,
    bus_off: bool,
    overrun: bool,
    sent: Vec<RawFrame>,
    scratch: Vec<RawFrame>,
    ticked_ns: u64,
}

impl Inner {
    /// Lets the drives' time pass to the clock's now (once per instant).
    fn tick(&mut self) {
        let now = self.clock.now_ns();
        if now == self.ticked_ns {
            return;
        }
        self.ticked_ns = now;
        for d in self.drives.iter_mut() {
            d.tick(now, &mut self.scratch);
        }
        self.queue();
    }

    fn queue(&mut self) {
        let frames: Vec<RawFrame> = self.scratch.drain(..).collect();
        for f in frames {
            if self.bus_off {
                continue;
            }
            if self.to_host.len() >= HOST_QUEUE {
                self.overrun = true;
            } else {
                self.to_host.push_back(f);
            }
        }
    }
}

/// The in-memory bus (cheap to clone: every clone is the same bus).
#[derive(Debug, Clone)]
pub struct MemBus {
    inner: Rc<RefCell<Inner>>,
}

impl MemBus {
    /// An empty bus on `clock`.
    pub fn new(clock: SimClock) -> Self {
        Self {
            inner: Rc::new(RefCell::new(Inner {
                clock,
                drives: Vec::new(),
                to_host: VecDeque::new(),
                errors: VecDeque::new(),
                bus_off: false,
                overrun: false,
                sent: Vec::new(),
                scratch: Vec::new(),
                ticked_ns: u64::MAX,
            })),
        }
    }

    /// Puts a drive on the bus; returns its index.
    pub fn add_drive(&self, drive: SimCia402Drive) -> usize {
        let mut inner = self.inner.borrow_mut();
        inner.drives.push(drive);
        inner.drives.len() - 1
    }

    /// The host's end of the bus.
    pub fn can(&self) -> MemCan {
        MemCan {
            inner: Rc::clone(&self.inner),
        }
    }

    /// Lets the drives' time pass to the clock's now (the host's receive
    /// does the same whenever the clock has moved).
    pub fn tick(&self) {
        self.inner.borrow_mut().tick();
    }

    /// Runs `f` on drive `index` (None if there is none); what the drive
    /// sends meanwhile goes on the bus.
    pub fn with_drive<R>(
        &self,
        index: usize,
        f: impl FnOnce(&mut SimCia402Drive, u64, &mut Vec<RawFrame>) -> R,
    ) -> Option<R> {
        let mut guard = self.inner.borrow_mut();
        let inner = &mut *guard;
        let now = inner.clock.now_ns();
        let r = inner
            .drives
            .get_mut(index)
            .map(|d| f(d, now, &mut inner.scratch));
        inner.queue();
        r
    }

    /// Reports an error frame (or overrun) to the host's next receive.
    pub fn inject_error(&self, error: MemBusError) {
        self.inner.borrow_mut().errors.push_back(error);
    }

    /// Puts the controller bus-off (or back on): while off, nothing is sent or
    /// received and every call of the host reports `BusOff`.
    pub fn set_bus_off(&self, off: bool) {
        let mut inner = self.inner.borrow_mut();
        inner.bus_off = off;
        if off {
            inner.to_host.clear();
        }
    }

    /// Takes the log of the frames the host sent (the last 65536).
    pub fn take_sent(&self) -> Vec<RawFrame> {
        core::mem::take(&mut self.inner.borrow_mut().sent)
    }
}

/// The host's end of a [`MemBus`].
#[derive(Debug)]
pub struct MemCan {
    inner: Rc<RefCell<Inner>>,
}

impl embedded_can::nb::Can for MemCan {
    type Frame = RawFrame;
    type Error = MemBusError;

    fn transmit(&mut self, frame: &RawFrame) -> nb::Result<Option<RawFrame>, MemBusError> {
        let mut guard = self.inner.borrow_mut();
        let inner = &mut *guard;
        if inner.bus_off {
            return Err(nb::Error::Other(MemBusError::BusOff));
        }
        if inner.sent.len() < LOG {
            inner.sent.push(*frame);
        }
        let now = inner.clock.now_ns();
        for d in inner.drives.iter_mut() {
            d.on_frame(frame, now, &mut inner.scratch);
        }
        inner.queue();
        Ok(None)
    }

    fn receive(&mut self) -> nb::Result<RawFrame, MemBusError> {
        let mut inner = self.inner.borrow_mut();
        inner.tick();
        if inner.bus_off {
            return Err(nb::Error::Other(MemBusError::BusOff));
        }
        if let Some(e) = inner.errors.pop_front() {
            return Err(nb::Error::Other(e));
        }
        if core::mem::take(&mut inner.overrun) {
            return Err(nb::Error::Other(MemBusError::Overrun));
        }
        inner.to_host.pop_front().ok_or(nb::Error::WouldBlock)
    }
}
