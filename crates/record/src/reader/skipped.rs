//! Corrupt records passed over ([`Skipped`]) and their tally
//! ([`SkippedTally`]).

/// A corrupt record passed over by [`McapReader::skip_bad_record`], or a
/// run of them one after the other ([`Skipped::absorb`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Skipped {
    /// Its offset in the file.
    pub offset: u64,
    /// Its length, prefix included (the bytes skipped).
    pub bytes: u64,
    /// The log times of its messages (a chunk's header, when readable), ns.
    pub log_time_ns: Option<(u64, u64)>,
    /// Why it was refused (the first of a run).
    pub why: String,
    /// The corrupt records in it: 1, or a run's length.
    pub records: u64,
}

impl Skipped {
    /// Takes `next` into this one when it starts where this one ends (a
    /// run of corrupt records is one part passed over); false otherwise.
    pub fn absorb(&mut self, next: &Skipped) -> bool {
        if self.bytes == 0
            || next.bytes == 0
            || self.offset.saturating_add(self.bytes) != next.offset
        {
            return false;
        }
        self.bytes = self.bytes.saturating_add(next.bytes);
        self.records = self.records.saturating_add(next.records);
        self.log_time_ns = match (self.log_time_ns, next.log_time_ns) {
            (Some((a, b)), Some((c, d))) => Some((a.min(c), b.max(d))),
            (a, b) => a.or(b),
        };
        true
    }

    /// "N bytes at byte X (why)", with the records of a run.
    pub fn describe(&self) -> String {
        format!(
            "{} bytes at byte {}{} ({})",
            self.bytes,
            self.offset,
            if self.records > 1 {
                format!(", {} corrupt records in a row", self.records)
            } else {
                String::new()
            },
            self.why
        )
    }
}

/// The most corrupt parts kept in detail ([`SkippedTally`]); the rest are
/// counted.
pub const MAX_SKIPPED_SHOWN: usize = 16;

/// The corrupt records a reading passed over, in bounded memory: the first
/// [`MAX_SKIPPED_SHOWN`] parts in detail (a run of records one after the
/// other is one part), and the count and bytes of every one.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct SkippedTally {
    /// The first parts, in file order.
    pub shown: Vec<Skipped>,
    /// Every corrupt record passed over.
    pub records: u64,
    /// Their bytes.
    pub bytes: u64,
    /// The parts (runs) in all, shown or not.
    pub parts: u64,
}

impl SkippedTally {
    /// Counts `s`; kept in detail if it continues the last part or there
    /// is room.
    pub fn add(&mut self, s: Skipped) {
        self.records = self.records.saturating_add(s.records);
        self.bytes = self.bytes.saturating_add(s.bytes);
        if let Some(last) = self.shown.last_mut()
            && last.absorb(&s)
        {
            return;
        }
        self.parts = self.parts.saturating_add(1);
        if self.shown.len() < MAX_SKIPPED_SHOWN {
            self.shown.push(s);
        }
    }

    /// Whether nothing was passed over.
    pub fn is_empty(&self) -> bool {
        self.records == 0
    }

    /// One line: how many records and bytes in how many parts, the first
    /// ones named.
    pub fn summary(&self) -> String {
        let shown: Vec<String> = self.shown.iter().map(Skipped::describe).collect();
        format!(
            "{} corrupt records ({} bytes) in {} part(s) passed over{}: {}",
            self.records,
            self.bytes,
            self.parts,
            if self.parts > self.shown.len() as u64 {
                format!(", the first {} named", self.shown.len())
            } else {
                String::new()
            },
            shown.join("; ")
        )
    }
}
