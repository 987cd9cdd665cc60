//! `sarctl replay [--config FILE] --input REC.mcap|DIR [--input ...] --output
//! OUT.mcap [--from S] [--to S] [--compare TOPIC] [--format json] [--plot
//! FILE.svg]`: the per-cycle step over a recording's inputs
//! ([`sar_record::replay`]; the files of a rotated set, or a directory of
//! them, replayed in order as one and checked to chain), its outputs
//! written, the recorded outputs compared bit for bit (a difference exits
//! non-zero naming the first cycle, topic and field), the error figures
//! against a reference topic, and the tip force over time as an SVG (the
//! article's Figure 9). Without `--config`, the configuration the recording
//! carries (`sar_config` metadata, written by `sard`).

use sar_record::output::{PendingFile, check_outputs};
use sar_record::replay::{
    AxisError, Comparison, ReplayOptions, ReplayReport, SeriesPoint, replay_files,
};
use serde_json::json;
use std::path::{Path, PathBuf};

/// The command's arguments.
#[derive(Debug, Clone, Copy)]
pub struct Args<'a> {
    /// The configuration (`None`: the one the recording carries).
    pub config: Option<&'a Path>,
    /// The recording: files of one rotated set in order, or directories
    /// (their `*.mcap` files by name, scene files left out).
    pub input: &'a [PathBuf],
    /// The outputs.
    pub output: Option<&'a Path>,
    /// The reference topic.
    pub compare: Option<&'a str>,
    /// One JSON object on stdout.
    pub json: bool,
    /// The SVG plot.
    pub plot: Option<&'a Path>,
    /// `--from`, s after the first cycle.
    pub from_s: Option<f64>,
    /// `--to`, s after the first cycle.
    pub to_s: Option<f64>,
}

/// The report as JSON.
pub fn report_json(r: &ReplayReport) -> serde_json::Value {
    json!({
        "mode": r.mode.name(),
        "cycles": r.cycles,
        "outputs": r.outputs,
        "compared": r.compared,
        "identical": r.differences == 0,
        "differences": r.differences,
        "first_difference": r.first_difference.as_ref().map(|d| json!({
            "cycle": d.cycle, "topic": d.topic, "field": d.field,
            "recorded": d.recorded, "replayed": d.replayed})),
        "recorder_dropped": r.recorder_dropped,
        "input_complete": r.input_complete,
        "stopped": r.stopped,
        "output": r.output.as_ref().map(|p| p.display().to_string()),
        "from_first_cycle": r.from_first_cycle,
        "from_snapshot": r.from_snapshot,
        "skipped_cycles": r.skipped_cycles,
        "snapshots_compared": r.snapshots_compared,
        "gaps_total": r.gaps_total,
        "corrupt_records": r.corrupt_records,
        "corrupt_bytes": r.corrupt_bytes,
        "gaps": r.gaps.iter().map(|g| json!({
            "file": g.file.as_ref().map(|f| f.display().to_string()),
            "offset": g.skipped.offset,
            "bytes": g.skipped.bytes,
            "log_time_ns": g.skipped.log_time_ns,
            "why": g.skipped.why,
            "corrupt_records": g.skipped.records,
            "last_cycle_before": g.last_cycle_before,
            "first_cycle_after": g.first_cycle_after,
            "cycles_lost": g.cycles_lost(),
            "cycles_not_replayed": g.cycles_not_replayed,
            "resumed_after_cycle": g.resumed_after_cycle,
        })).collect::<Vec<_>>(),
        "comparison": r.comparison.as_ref().map(|c| json!({
            "topic": c.topic,
            "pairs": c.pairs,
            "left_out": c.left_out,
            "e_ra": c.axes.iter().map(|a| a.e_ra).collect::<Vec<_>>(),
            "rms_n": c.axes.iter().map(|a| a.rms_n).collect::<Vec<_>>(),
            "max_n": c.axes.iter().map(|a| a.max_n).collect::<Vec<_>>(),
        })),
    })
}

/// Runs the command.
pub fn run(a: &Args<'_>) -> Result<(), String> {
    let inputs = input_files(a.input)?;
    let first = inputs.first().ok_or("replay needs --input REC.mcap")?;
    // Every file written is none of the files read (by device and inode:
    // a hard or symbolic link is the file), and --output and --plot differ.
    let mut read: Vec<&Path> = inputs.iter().map(PathBuf::as_path).collect();
    read.extend(a.config);
    let written: Vec<&Path> = a.output.into_iter().chain(a.plot).collect();
    check_outputs(&written, &read).map_err(|e| e.to_string())?;
    let cfg = configuration(a.config, first)?;
    let options = ReplayOptions {
        output: a.output.map(Path::to_path_buf),
        compare: a.compare.map(str::to_owned),
        keep_series: a.plot.is_some(),
        from_s: a.from_s,
        to_s: a.to_s,
        ..ReplayOptions::from_config(&cfg)
    };
    let shown = shown(&inputs);
    let r = replay_files(&inputs, &options).map_err(|e| format!("{shown}: {e}"))?;
    if let Some(plot) = a.plot {
        plot_svg(plot, &r.series, a.compare)?;
    }
    if a.json {
        println!("{}", report_json(&r));
    } else {
        print_text(&r, &shown);
    }
    verdict(&r, &shown, inputs.len())
}

/// The configuration at `path`, else the one recorded in `first` (the
/// recording's first file); an error when it carries none.
fn configuration(path: Option<&Path>, first: &Path) -> Result<sar_config::Config, String> {
    if let Some(path) = path {
        return sar_config::load(path).map_err(|e| e.to_string());
    }
    let source = sar_record::replay::recorded_config(first)
        .map_err(|e| match e {
            // These name the file themselves.
            sar_record::ReadError::Io { .. } | sar_record::ReadError::NotRegular { .. } => {
                e.to_string()
            }
            e => format!("{}: {e}", first.display()),
        })?
        .ok_or_else(|| {
            format!(
                "{}: the recording carries no configuration (not written by sard, or by an older one): give --config FILE",
                first.display()
            )
        })?;
    let origin = format!(
        "the configuration recorded in {} (from {})",
        first.display(),
        source.origin
    );
    sar_config::parse(&source.toml, &origin).map_err(|e| e.to_string())
}

/// The inputs as the messages name them: the file, or the first and the
/// last of several.
fn shown(inputs: &[PathBuf]) -> String {
    match inputs {
        [one] => one.display().to_string(),
        [first, .., last] => format!(
            "{} .. {} ({} files)",
            first.display(),
            last.display(),
            inputs.len()
        ),
        [] => String::new(),
    }
}

/// The text report: what was replayed, compared and passed over.
fn print_text(r: &ReplayReport, shown: &str) {
    println!(
        "{}: {} cycles replayed ({}), {} outputs{}",
        shown,
        r.cycles,
        r.mode.name(),
        r.outputs,
        r.output
            .as_ref()
            .map(|p| format!(" written to {}", p.display()))
            .unwrap_or_default()
    );
    if let Some(c) = r.from_snapshot {
        println!(
            "started from the snapshot after cycle {c} ({} earlier cycles in the file skipped)",
            r.skipped_cycles
        );
    }
    if r.snapshots_compared > 0 {
        println!(
            "{} recorded snapshots compared with the replayed state",
            r.snapshots_compared
        );
    }
    if r.compared > 0 || r.differences > 0 {
        println!(
            "compared with the recorded outputs: {} messages, {} differ",
            r.compared, r.differences
        );
    }
    if let Some(c) = &r.comparison {
        println!("{}", comparison_line(c));
    }
    for g in &r.gaps {
        println!("{}", gap_line(g));
    }
    if r.gaps_total > r.gaps.len() as u64 {
        println!(
            "... and {} more part(s) not replayed (the first {} named)",
            r.gaps_total - r.gaps.len() as u64,
            r.gaps.len()
        );
    }
    if let Some(e) = &r.stopped {
        println!("the input is cut short: replayed up to its last complete chunk ({e})");
    }
}

/// The error figures against the reference topic, X Y Z.
fn comparison_line(c: &Comparison) -> String {
    let xyz = |figure: fn(&AxisError) -> f64, digits: usize| {
        let v: Vec<String> = c
            .axes
            .iter()
            .map(|a| format!("{:.*}", digits, figure(a)))
            .collect();
        v.join(" ")
    };
    format!(
        "against {} ({} pairs, {} left out): e_ra {}, RMS {} N, max {} N (X Y Z)",
        c.topic,
        c.pairs,
        c.left_out,
        xyz(|a| a.e_ra, 4),
        xyz(|a| a.rms_n, 3),
        xyz(|a| a.max_n, 3)
    )
}

/// The exit: an error for a part not replayed (never exit 0 over one), an
/// input cut short, no cycle replayable, or a difference from the
/// recording (`files` inputs: with several, the file is named).
fn verdict(r: &ReplayReport, shown: &str, files: usize) -> Result<(), String> {
    if let Some(g) = r.gaps.first() {
        return Err(format!(
            "{shown}: {} part(s) not replayed (corrupt, or cycles missing){}; the first: {}",
            r.gaps_total,
            if r.corrupt_records > 0 {
                format!(
                    ", {} corrupt records ({} bytes) passed over",
                    r.corrupt_records, r.corrupt_bytes
                )
            } else {
                String::new()
            },
            gap_line(g)
        ));
    }
    if let Some(e) = &r.stopped {
        return Err(format!(
            "{e}: replayed {} cycles up to its last complete chunk; `sarctl recover` rewrites a file cut short (then replay that)",
            r.cycles
        ));
    }
    if r.cycles == 0 && r.skipped_cycles > 0 {
        return Err(format!(
            "{shown}: no snapshot of the loop's state in the recording (all dropped?): its {} cycles cannot be replayed",
            r.skipped_cycles
        ));
    }
    match &r.first_difference {
        Some(d) => Err(format!(
            "replay differs from the recording: {} messages; first {}at cycle {} on {} field {} (recorded {}, replayed {}){}",
            r.differences,
            d.file
                .as_ref()
                .filter(|_| files > 1)
                .map(|f| format!("in {} ", f.display()))
                .unwrap_or_default(),
            d.cycle,
            d.topic,
            d.field,
            d.recorded,
            d.replayed,
            if r.from_first_cycle == Some(false) && r.from_snapshot.is_none() {
                "; the recording starts after the daemon's first cycle (sarctl record start, or a later file of a rotation), so the estimator's earlier state is not in it"
            } else {
                ""
            }
        )),
        None => Ok(()),
    }
}

/// One line for a corrupt part passed over: where, how much, what was lost.
fn gap_line(g: &sar_record::replay::Gap) -> String {
    if g.skipped.bytes == 0 {
        // Cycles missing between two good chunks (no corrupt bytes here).
        return format!(
            "{}{}{}",
            g.skipped.why,
            g.file
                .as_ref()
                .map(|f| format!(" in {}", f.display()))
                .unwrap_or_default(),
            match g.resumed_after_cycle {
                Some(c) => format!(
                    "; {} cycles after them not replayed, replay went on from the snapshot after cycle {c}",
                    g.cycles_not_replayed
                ),
                None => format!(
                    "; the {} cycles read after them were not replayed (no snapshot after them)",
                    g.cycles_not_replayed
                ),
            }
        );
    }
    format!(
        "corrupt part passed over: {} bytes at byte {}{}{}{} ({}); {}{}",
        g.skipped.bytes,
        g.skipped.offset,
        if g.skipped.records > 1 {
            format!(" ({} corrupt records in a row)", g.skipped.records)
        } else {
            String::new()
        },
        g.file
            .as_ref()
            .map(|f| format!(" of {}", f.display()))
            .unwrap_or_default(),
        g.skipped
            .log_time_ns
            .map(|(a, b)| format!(", log time {a}..{b} ns"))
            .unwrap_or_default(),
        g.skipped.why,
        match (g.cycles_lost(), g.last_cycle_before) {
            (Some(n), Some(c)) => format!("{n} cycles lost in it (after cycle {c})"),
            (None, Some(c)) => format!("nothing read after it (last cycle {c})"),
            _ => "before the first cycle".to_owned(),
        },
        match g.resumed_after_cycle {
            Some(c) => format!(
                "; {} cycles after it not replayed, replay went on from the snapshot after cycle {c}",
                g.cycles_not_replayed
            ),
            None if g.cycles_not_replayed > 0 => format!(
                "; the {} cycles read after it were not replayed (no snapshot after it)",
                g.cycles_not_replayed
            ),
            None => String::new(),
        }
    )
}

/// The files to replay: each input as given, a directory as its `*.mcap`
/// files sorted by name (the recorder's `NAME-0000.mcap`, `NAME-0001.mcap`,
/// ...), without the scene companions. A directory with none is an error.
pub fn input_files(inputs: &[PathBuf]) -> Result<Vec<PathBuf>, String> {
    let mut out = Vec::new();
    for input in inputs {
        if input.is_dir() {
            let entries = std::fs::read_dir(input)
                .map_err(|e| format!("{}: cannot list the directory: {e}", input.display()))?;
            let mut files: Vec<PathBuf> = entries
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| {
                    let name = p.to_string_lossy();
                    name.ends_with(".mcap") && !name.ends_with(".scene.mcap")
                })
                .collect();
            if files.is_empty() {
                return Err(format!(
                    "{}: no .mcap file in the directory",
                    input.display()
                ));
            }
            files.sort();
            out.extend(files);
        } else {
            out.push(input.clone());
        }
    }
    Ok(out)
}

/// The tip force over time (X, Y, Z, one panel each) with the reference
/// when there is one, as an SVG.
pub fn plot_svg(
    path: &Path,
    series: &[SeriesPoint],
    reference: Option<&str>,
) -> Result<(), String> {
    use plotters::prelude::*;
    let err = |e: &dyn std::fmt::Display| format!("{}: cannot draw the plot: {e}", path.display());
    let t_max = series.last().map_or(1.0, |p| p.t_s).max(1e-3);
    let (lo, hi) = force_range_n(series);
    let pad = ((hi - lo) * 0.05).max(0.1);
    // Drawn into a temporary file beside it, renamed over it once whole.
    let pending = PendingFile::new(path).map_err(|e| err(&e))?;
    let tmp = pending.tmp_path().to_path_buf();
    let root = SVGBackend::new(&tmp, (1200, 900)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let panels = root.split_evenly((3, 1));
    for (k, area) in panels.iter().enumerate() {
        let panel = Panel {
            k,
            t_max,
            force_n: (lo - pad)..(hi + pad),
        };
        draw_panel(area, &panel, series, reference).map_err(|e| err(&e))?;
    }
    root.present().map_err(|e| err(&e))?;
    drop(root);
    pending.commit().map_err(|e| err(&e))?;
    Ok(())
}

/// (min, max) of the estimate and the reference over `series`, N
/// ((-1, 1) when none is finite).
fn force_range_n(series: &[SeriesPoint]) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for p in series {
        for v in p.estimate_n.iter().chain(p.reference_n.iter().flatten()) {
            if v.is_finite() {
                lo = lo.min(*v);
                hi = hi.max(*v);
            }
        }
    }
    if !lo.is_finite() {
        (lo, hi) = (-1.0, 1.0);
    }
    (lo, hi)
}

/// One panel of [`plot_svg`]: axis `k` (0 = X) over `0..t_max` s and the
/// force range, N.
struct Panel {
    k: usize,
    t_max: f64,
    force_n: std::ops::Range<f64>,
}

/// Draws the force along one axis over time: the reference (when there is
/// one), the estimate and the legend.
fn draw_panel<DB: plotters::prelude::DrawingBackend>(
    area: &plotters::prelude::DrawingArea<DB, plotters::coord::Shift>,
    panel: &Panel,
    series: &[SeriesPoint],
    reference: Option<&str>,
) -> Result<(), plotters::prelude::DrawingAreaErrorKind<DB::ErrorType>> {
    use plotters::prelude::*;
    let k = panel.k;
    let axis = ["X", "Y", "Z"].get(k).copied().unwrap_or("?");
    let mut chart = ChartBuilder::on(area)
        .caption(
            format!("tip force F_tip {axis}, base frame (the article's Figure 9)"),
            ("sans-serif", 16),
        )
        .margin(8)
        .x_label_area_size(30)
        .y_label_area_size(50)
        .build_cartesian_2d(0.0..panel.t_max, panel.force_n.clone())?;
    chart
        .configure_mesh()
        .x_desc("t (s)")
        .y_desc(format!("F_{axis} (N)"))
        .draw()?;
    let colour = [RED, GREEN, BLUE].get(k).copied().unwrap_or(BLACK);
    if let Some(topic) = reference {
        chart
            .draw_series(LineSeries::new(
                series
                    .iter()
                    .filter_map(|p| Some((p.t_s, *p.reference_n?.get(k)?))),
                BLACK.stroke_width(2),
            ))?
            .label(format!("reference {topic}"))
            .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], BLACK));
    }
    chart
        .draw_series(LineSeries::new(
            series
                .iter()
                .filter_map(|p| Some((p.t_s, *p.estimate_n.get(k)?))),
            colour.mix(0.7),
        ))?
        .label("estimate (unfiltered, observable)")
        .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], colour));
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
}
