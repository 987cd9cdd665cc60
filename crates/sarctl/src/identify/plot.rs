//! The figure of an identification (`sarctl identify --plot FILE.svg`): the
//! vertical force at A against X = 1/a, with the fitted straight line
//! F = m |g| - M |g| X of the article's Figure 6 (exact for a horizontal rod at
//! the support's height, MODEL.md 5), the full model's value at each pose, and
//! below the residuals (measured - model) of the vertical force. SVG only
//! (plotters' SVG backend writes text as SVG `<text>`: no font files needed).

use super::Identified;
use plotters::prelude::*;

pub(super) fn err(e: impl std::fmt::Display) -> String {
    format!("the figure could not be drawn: {e}")
}

/// (min, max) widened by 5 % of the span on each side (and never empty).
pub(super) fn range(values: impl Iterator<Item = f64> + Clone) -> (f64, f64) {
    let lo = values.clone().fold(f64::INFINITY, f64::min);
    let hi = values.fold(f64::NEG_INFINITY, f64::max);
    if !(lo.is_finite() && hi.is_finite()) {
        return (0.0, 1.0);
    }
    let pad = ((hi - lo) * 0.05).max(1e-6);
    (lo - pad, hi + pad)
}

/// The figure's data: per pose (X = 1/a, measured, model) of the vertical
/// force, N; the fitted line's ends; the axes' ranges.
struct Figure {
    pts: Vec<(f64, f64, f64)>,
    line: [(f64, f64); 2],
    x: (f64, f64),
    y: (f64, f64),
    residuals: Vec<(f64, f64)>,
    r: (f64, f64),
}

/// The vertical force at each pose, the line F = m |g| - M |g| X and the
/// residuals, with the ranges that hold them.
fn figure(result: &Identified) -> Figure {
    let g = nalgebra::Vector3::from(result.gravity_mps2);
    let g_norm = g.norm();
    let up = -g / g_norm;
    // (X, measured, model) per pose.
    let pts: Vec<(f64, f64, f64)> = result
        .used
        .iter()
        .map(|p| {
            (
                1.0 / p.support_distance_m,
                p.measured_n.dot(&up),
                p.model_n.dot(&up),
            )
        })
        .collect();
    let (x0, x1) = range(pts.iter().map(|p| p.0).chain([0.0]));
    let line = |x: f64| result.mass_kg * g_norm - result.moment_kgm * g_norm * x;
    let y = range(
        pts.iter()
            .flat_map(|p| [p.1, p.2])
            .chain([line(x0), line(x1)]),
    );
    let residuals: Vec<(f64, f64)> = pts.iter().map(|p| (p.0, p.1 - p.2)).collect();
    let r = range(residuals.iter().map(|r| r.1).chain([0.0]));
    Figure {
        pts,
        line: [(x0, line(x0)), (x1, line(x1))],
        x: (x0, x1),
        y,
        residuals,
        r,
    }
}

/// The SVG text of the figure.
pub fn svg(result: &Identified) -> Result<String, String> {
    let f = figure(result);
    let mut out = String::new();
    {
        let root = SVGBackend::with_string(&mut out, (900, 820)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let (upper, lower) = root.split_vertically(520);
        draw_fit(&upper, result, &f).map_err(err)?;
        draw_residuals(&lower, result, &f).map_err(err)?;
        root.present().map_err(err)?;
    }
    Ok(out)
}

/// The chart of one panel: its caption (text, font size), X = 1/a over
/// `x` and `y_desc` over `y`.
fn panel<'a, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, plotters::coord::Shift>,
    (caption, font_size): (String, i32),
    x: (f64, f64),
    y: (f64, f64),
    y_desc: &str,
) -> Result<Chart<'a, DB>, DrawingAreaErrorKind<DB::ErrorType>> {
    let mut chart = ChartBuilder::on(area)
        .caption(caption, ("sans-serif", font_size))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(x.0..x.1, y.0..y.1)?;
    chart
        .configure_mesh()
        .x_desc("X = 1/a (1/m)")
        .y_desc(y_desc)
        .draw()?;
    Ok(chart)
}

/// A chart of f64 over f64.
type Chart<'a, DB> = ChartContext<
    'a,
    DB,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

/// The upper panel: the fitted line, the full model and the measured force
/// at each pose, against X = 1/a.
fn draw_fit<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    result: &Identified,
    f: &Figure,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let caption = format!(
        "vertical force at A against 1/a: m = {:.4} kg, c = {:.5} m",
        result.mass_kg, result.com_m
    );
    let mut chart = panel(area, (caption, 20), f.x, f.y, "F_A up (N)")?;
    chart
        .draw_series(LineSeries::new(f.line, RED.stroke_width(2)))?
        .label("m|g| - M|g| X (fitted line)")
        .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], RED));
    chart
        .draw_series(
            f.pts
                .iter()
                .map(|&(x, _, model)| Cross::new((x, model), 5, GREEN.stroke_width(2))),
        )?
        .label("full model at each pose")
        .legend(|(x, y)| Cross::new((x + 10, y), 5, GREEN.stroke_width(2)));
    chart
        .draw_series(
            f.pts
                .iter()
                .map(|&(x, measured, _)| Circle::new((x, measured), 4, BLUE.filled())),
        )?
        .label("measured (dwell mean)")
        .legend(|(x, y)| Circle::new((x + 10, y), 4, BLUE.filled()));
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
}

/// The lower panel: the residuals (measured - model) against X = 1/a.
fn draw_residuals<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    result: &Identified,
    f: &Figure,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let (x0, x1) = f.x;
    let caption = format!(
        "residuals (measured - model), RMS {:.3} N, chi2/dof {:.2}",
        result.residual_rms_n, result.chi2_dof
    );
    let mut res = panel(area, (caption, 18), f.x, f.r, "residual (N)")?;
    res.draw_series(LineSeries::new([(x0, 0.0), (x1, 0.0)], BLACK))?;
    res.draw_series(
        f.residuals
            .iter()
            .map(|&(x, r)| Circle::new((x, r), 4, BLUE.filled())),
    )?;
    Ok(())
}
