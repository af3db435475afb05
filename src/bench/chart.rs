//! What both benches share: the Pareto front, and charts drawn once for SVG and PNG in the house
//! style (fonts, margins, legends).

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use plotters::coord::Shift;
use plotters::coord::combinators::LogCoord;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

use crate::AppError;

/// Marks the points no other point beats on both axes (lower is better on each): no other
/// point is at most as costly and at most as bad with one of the two strictly lower.
/// Non-finite points are never on the front.
pub fn pareto_front(cost: &[f64], bad: &[f64]) -> Vec<bool> {
    let ok = |i: usize| cost[i].is_finite() && bad[i].is_finite();
    (0..cost.len())
        .map(|i| {
            ok(i)
                && !(0..cost.len()).any(|j| {
                    j != i
                        && ok(j)
                        && cost[j] <= cost[i]
                        && bad[j] <= bad[i]
                        && (cost[j] < cost[i] || bad[j] < bad[i])
                })
        })
        .collect()
}

/// Font files tried for chart text, first found wins; `AVATARM_FONT` goes first.
const FONT_FILES: [&str; 3] = [
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/TTF/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",
];

/// Registers a system font as plotters' "sans-serif" (once per process). Errors: no font file
/// found ([`AppError::NoFont`]), or the first one found is not a usable TrueType font.
pub fn register_font() -> Result<(), AppError> {
    // Err(None): no file found; Err(Some(path)): the file found is not a font.
    static DONE: OnceLock<Result<(), Option<PathBuf>>> = OnceLock::new();
    let done = DONE.get_or_init(|| {
        let env = std::env::var_os("AVATARM_FONT").map(PathBuf::from);
        let candidates = env.into_iter().chain(FONT_FILES.iter().map(PathBuf::from));
        for path in candidates {
            let Ok(bytes) = std::fs::read(&path) else {
                continue;
            };
            let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
            return plotters::style::register_font("sans-serif", FontStyle::Normal, bytes)
                .map_err(|_| Some(path));
        }
        Err(None)
    });
    match done {
        Ok(()) => Ok(()),
        Err(None) => Err(AppError::NoFont {
            searched: FONT_FILES.join(", "),
        }),
        Err(Some(path)) => Err(AppError::Chart {
            what: path.display().to_string(),
            source: "not a usable TrueType font".into(),
        }),
    }
}

/// A drawing error of any plotters backend as an [`AppError::Chart`].
pub fn drawing_error<E: std::error::Error + Send + Sync + 'static>(
    e: DrawingAreaErrorKind<E>,
) -> AppError {
    AppError::Chart {
        what: "drawing".into(),
        source: Box::new(e),
    }
}

/// A chart drawn the same way on any plotters backend.
pub trait Chart {
    /// Draws onto `root`.
    fn draw<DB: DrawingBackend>(&self, root: DrawingArea<DB, Shift>) -> Result<(), AppError>
    where
        DB::ErrorType: 'static;
}

/// Draws `chart` to `svg` and, at the same size, to `png`.
pub fn save_chart(
    chart: &impl Chart,
    size: (u32, u32),
    svg: &Path,
    png: &Path,
) -> Result<(), AppError> {
    register_font()?;
    fn named(path: &Path) -> impl Fn(AppError) -> AppError + '_ {
        move |e| match e {
            AppError::Chart { source, .. } => AppError::Chart {
                what: path.display().to_string(),
                source,
            },
            other => other,
        }
    }
    chart
        .draw(SVGBackend::new(svg, size).into_drawing_area())
        .map_err(named(svg))?;
    let (w, h) = size;
    let mut buf = vec![0u8; (w * h * 3) as usize];
    chart
        .draw(BitMapBackend::with_buffer(&mut buf, size).into_drawing_area())
        .map_err(named(png))?;
    image::RgbImage::from_raw(w, h, buf)
        .ok_or_else(|| AppError::ImageSize {
            what: png.display().to_string(),
            width: w,
            height: h,
        })?
        .save(png)
        .map_err(|source| AppError::write_image(png, source))
}

/// The axis range of some values with a margin; `(0, 1)` when none is finite.
pub fn padded(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
            (a.min(x), b.max(x))
        });
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    let pad = ((hi - lo) * 0.12).max(hi.abs() * 0.02).max(1e-3);
    (lo - pad, hi + pad)
}

/// A scatter/line panel on `area` with labelled axes over `x` × `y`.
pub type Panel<'a, DB> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// A panel like [`Panel`] whose y axis is logarithmic.
pub type LogPanel<'a, DB> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, LogCoord<f64>>>;

/// The house style's margins and label areas.
fn builder<'a, 'b, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
) -> ChartBuilder<'a, 'b, DB> {
    let mut b = ChartBuilder::on(area);
    b.margin(18).x_label_area_size(48).y_label_area_size(64);
    b
}

/// Builds a panel with the house style (margins, fonts, grid).
pub fn axes<'a, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
    x: (f64, f64),
    y: (f64, f64),
    x_desc: &str,
    y_desc: &str,
) -> Result<Panel<'a, DB>, AppError>
where
    DB::ErrorType: 'static,
{
    let err = drawing_error::<DB::ErrorType>;
    let mut chart = builder(area)
        .build_cartesian_2d(x.0..x.1, y.0..y.1)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .label_style(("sans-serif", 14))
        .axis_desc_style(("sans-serif", 16))
        .draw()
        .map_err(err)?;
    Ok(chart)
}

/// [`axes`] with a logarithmic y axis over `y` (both ends > 0).
pub fn log_axes<'a, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
    x: (f64, f64),
    y: (f64, f64),
    x_desc: &str,
    y_desc: &str,
) -> Result<LogPanel<'a, DB>, AppError>
where
    DB::ErrorType: 'static,
{
    let err = drawing_error::<DB::ErrorType>;
    let mut chart = builder(area)
        .build_cartesian_2d(x.0..x.1, (y.0..y.1).log_scale())
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .label_style(("sans-serif", 14))
        .axis_desc_style(("sans-serif", 16))
        .draw()
        .map_err(err)?;
    Ok(chart)
}

/// Draws the panel's legend at `position`.
pub fn legend<'a, DB: DrawingBackend + 'a, CT: CoordTranslate>(
    chart: &mut ChartContext<'a, DB, CT>,
    position: SeriesLabelPosition,
) -> Result<(), AppError>
where
    DB::ErrorType: 'static,
{
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", 14))
        .position(position)
        .draw()
        .map_err(drawing_error)
}

/// Writes a bench's CSV table: `header`, then one line per row.
pub fn write_table(
    path: &Path,
    header: &str,
    rows: impl IntoIterator<Item = String>,
) -> Result<(), AppError> {
    let mut text = format!("{header}\n");
    for row in rows {
        text.push_str(&row);
        text.push('\n');
    }
    std::fs::write(path, text).map_err(|e| AppError::write(path, e))
}

/// Draws the Pareto front through `points` as a red line (in order of cost), with its legend
/// entry.
pub fn front_line<'a, DB: DrawingBackend + 'a>(
    chart: &mut Panel<'a, DB>,
    mut points: Vec<(f64, f64)>,
) -> Result<(), AppError>
where
    DB::ErrorType: 'static,
{
    points.sort_by(|a, b| a.0.total_cmp(&b.0));
    chart
        .draw_series(LineSeries::new(points, RED.stroke_width(2)))
        .map_err(drawing_error)?
        .label("Pareto front")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], RED.stroke_width(2)));
    Ok(())
}

/// Writes each label above and right of its point.
pub fn point_labels<'a, DB: DrawingBackend + 'a>(
    chart: &mut Panel<'a, DB>,
    labels: impl IntoIterator<Item = ((f64, f64), String)>,
) -> Result<(), AppError>
where
    DB::ErrorType: 'static,
{
    chart
        .draw_series(labels.into_iter().map(|(at, text)| {
            EmptyElement::at(at)
                + Text::new(
                    text,
                    (10, -18),
                    ("sans-serif", 13).into_font().color(&BLACK),
                )
        }))
        .map_err(drawing_error)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pareto_front_keeps_the_undominated_points() {
        let cost = [1.0, 2.0, 3.0, 2.0, 4.0, f64::NAN];
        let bad = [5.0, 3.0, 1.0, 4.0, 1.0, 0.0];
        // (2, 4) is beaten by (2, 3); (4, 1) by (3, 1); NaN never counts.
        assert_eq!(
            pareto_front(&cost, &bad),
            [true, true, true, false, false, false]
        );
        // Equal points do not dominate each other.
        assert_eq!(pareto_front(&[1.0, 1.0], &[2.0, 2.0]), [true, true]);
    }
}
