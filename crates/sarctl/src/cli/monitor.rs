//! `sarctl monitor [--count N]`: the live state. On a terminal (text), a
//! view redrawn every 0.1 s: the state's line, a bar of |F_tip| against the
//! stop limit and ten seconds of history; otherwise one line per sample
//! (`--format json`: one JSON object per sample). It stops after `N`
//! samples, or fails when the daemon stops publishing for 2 s.

use super::output_error;
use super::status::{state_json, state_line};
use sar_msgs::wire::StateMsg;
use sar_shm::{Client, StateSubscription};
use std::io::{IsTerminal, Write};
use std::time::{Duration, Instant};

/// `--count N`: at least one sample (0 printed one sample before; a count
/// of nothing has no use, so it is refused, not taken as "none").
pub fn parse_count(text: &str) -> Result<u64, String> {
    match text.parse::<u64>() {
        Ok(0) => {
            Err("must be at least 1 (without --count, monitor runs until interrupted)".to_owned())
        }
        Ok(n) => Ok(n),
        Err(e) => Err(format!("{e}")),
    }
}

/// Runs the command; `count` stops after that many samples.
pub fn run(client: &Client, json: bool, count: Option<u64>) -> Result<(), String> {
    let sub = client.subscribe().map_err(|e| e.to_string())?;
    let mut monitor = Monitor {
        json,
        live: !json && std::io::stdout().is_terminal(),
        count,
        seen: 0,
        history: Vec::new(),
        last_print: Instant::now(),
    };
    let mut stdout = std::io::stdout().lock();
    let mut idle = Instant::now();
    loop {
        let batch = next_batch(&sub, &mut idle)?;
        if monitor.print_samples(&mut stdout, &batch)? {
            return Ok(());
        }
        monitor.draw_live(&mut stdout, &batch)?;
    }
}

/// The states published within 200 ms (none: waits again); an error when
/// nothing came for 2 s since `idle`, the last state.
fn next_batch(sub: &StateSubscription, idle: &mut Instant) -> Result<Vec<StateMsg>, String> {
    loop {
        let mut batch: Vec<StateMsg> = Vec::new();
        sub.wait(Duration::from_millis(200), |s| batch.push(*s));
        if !batch.is_empty() {
            *idle = Instant::now();
            return Ok(batch);
        }
        if idle.elapsed() > Duration::from_secs(2) {
            return Err("the daemon stopped publishing".to_owned());
        }
    }
}

/// What `monitor` has shown so far.
struct Monitor {
    /// One JSON object per sample.
    json: bool,
    /// Text on a terminal: the redrawn view instead of lines.
    live: bool,
    /// Stop after this many samples.
    count: Option<u64>,
    /// Samples seen.
    seen: u64,
    /// The live view's history, one glyph per 0.1 s, the last 60.
    history: Vec<char>,
    /// When the live view was last drawn.
    last_print: Instant,
}

impl Monitor {
    /// Prints each sample of `batch` as a line (JSON or text; none in the
    /// live view); true once `count` samples are seen.
    fn print_samples(&mut self, out: &mut impl Write, batch: &[StateMsg]) -> Result<bool, String> {
        for s in batch {
            self.seen += 1;
            if self.json {
                writeln!(out, "{}", state_json(s)).map_err(output_error)?;
            } else if !self.live {
                writeln!(out, "{}", state_line(s)).map_err(output_error)?;
            }
            if self.count.is_some_and(|c| self.seen >= c) {
                return Ok(true);
            }
        }
        Ok(false)
    }

    /// Redraws the live view from the last state of `batch`, at most every
    /// 0.1 s.
    fn draw_live(&mut self, out: &mut impl Write, batch: &[StateMsg]) -> Result<(), String> {
        if !(self.live && self.last_print.elapsed() > Duration::from_millis(100)) {
            return Ok(());
        }
        self.last_print = Instant::now();
        let Some(s) = batch.last() else {
            return Ok(());
        };
        let norm = s.tip_force_norm_n();
        self.history
            .push(history_glyph(norm, s.limits().stop_total_n));
        if self.history.len() > 60 {
            self.history.remove(0);
        }
        let h: String = self.history.iter().collect();
        write!(
            out,
            "\x1b[2J\x1b[H{}\n|F_tip| {:6.2} N [{}] stop {:.1} N\n{HISTORY_LEGEND}\nhistory (10 s) [{h}]\n",
            state_line(s),
            norm,
            bar(s),
            s.limits().stop_total_n
        )
        .map_err(output_error)?;
        out.flush().map_err(output_error)
    }
}

/// One symbol per tenth of a second: |F_tip| against the stop limit, in
/// ninths (`@`: at or above the stop limit).
const HISTORY_GLYPHS: [char; 10] = [' ', '.', ':', '-', '=', '+', '*', '#', '%', '@'];

/// The legend printed above `monitor`'s history line.
const HISTORY_LEGEND: &str = "history: one symbol per 0.1 s, |F_tip| as a share of the stop \
     limit: ' ' under 1/9, then . : - = + * # % in ninths, @ at or above the stop limit";

/// The glyph of |F_tip| = `norm` against the stop limit `stop`.
fn history_glyph(norm: f64, stop: f64) -> char {
    let level = ((norm / stop.max(1e-9)) * 9.0).clamp(0.0, 9.0) as usize;
    HISTORY_GLYPHS.get(level).copied().unwrap_or('@')
}

/// A bar of |F| against the stop limit, for the terminal view.
fn bar(s: &StateMsg) -> String {
    let norm = s.tip_force_norm_n();
    let stop = s.limits().stop_total_n.max(1e-9);
    let width = 40usize;
    let filled = ((norm / stop).clamp(0.0, 1.0) * width as f64).round() as usize;
    let warn_at =
        ((s.limits().warn_total_n / stop).clamp(0.0, 1.0) * width as f64).round() as usize;
    (0..width)
        .map(|i| {
            if i < filled {
                '#'
            } else if i == warn_at {
                '|'
            } else {
                '.'
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue 35: `monitor --count 0` printed one sample; 0 is refused.
    #[test]
    fn a_count_of_zero_is_refused() {
        assert!(
            parse_count("0")
                .unwrap_err()
                .starts_with("must be at least 1")
        );
        assert_eq!(parse_count("1"), Ok(1));
        assert_eq!(parse_count("5"), Ok(5));
        assert!(parse_count("-1").is_err());
    }

    #[test]
    fn the_history_legend_matches_the_glyphs() {
        // The glyphs between the blank and `@`, in order, then `@`.
        let middle: Vec<String> = HISTORY_GLYPHS[1..9].iter().map(char::to_string).collect();
        assert!(
            HISTORY_LEGEND.contains(&middle.join(" ")),
            "{HISTORY_LEGEND}"
        );
        assert!(HISTORY_LEGEND.contains("@ at or above"), "{HISTORY_LEGEND}");
        assert_eq!(history_glyph(0.0, 15.0), ' ');
        assert_eq!(history_glyph(15.0 / 9.0, 15.0), '.');
        assert_eq!(history_glyph(14.9, 15.0), '%');
        assert_eq!(history_glyph(15.0, 15.0), '@');
        assert_eq!(history_glyph(100.0, 15.0), '@');
    }
}
