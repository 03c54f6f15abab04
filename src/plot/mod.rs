//! PNG line plots for the `rbss` command: figures of one or more panels, each with named
//! series, optional log axes. Text uses the bundled DejaVu Sans (see DejaVuSans.LICENSE), so
//! plots render the same on any machine.

use std::path::Path;
use std::sync::Once;

use plotters::prelude::*;

static FONT: &[u8] = include_bytes!("DejaVuSans.ttf");
static REGISTER: Once = Once::new();

fn register_font() {
    REGISTER.call_once(|| {
        // The bundled font is valid; a failure here would only lose the text.
        let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, FONT);
    });
}

/// One curve.
#[derive(Debug, Clone)]
pub struct Series {
    pub name: String,
    pub x: Vec<f64>,
    pub y: Vec<f64>,
    /// Dashed-looking (drawn thinner and lighter) for reference curves.
    pub reference: bool,
    /// Mark every point with a dot (work-precision diagrams).
    pub markers: bool,
}

impl Series {
    pub fn new(name: impl Into<String>, x: Vec<f64>, y: Vec<f64>) -> Self {
        Series {
            name: name.into(),
            x,
            y,
            reference: false,
            markers: false,
        }
    }
    pub fn reference(mut self) -> Self {
        self.reference = true;
        self
    }
    pub fn markers(mut self) -> Self {
        self.markers = true;
        self
    }
}

/// One panel.
#[derive(Debug, Clone, Default)]
pub struct Panel {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub log_x: bool,
    pub log_y: bool,
    pub series: Vec<Series>,
}

impl Panel {
    pub fn new(
        title: impl Into<String>,
        x_label: impl Into<String>,
        y_label: impl Into<String>,
    ) -> Self {
        Panel {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            ..Default::default()
        }
    }
    pub fn log_y(mut self) -> Self {
        self.log_y = true;
        self
    }
    pub fn log_x(mut self) -> Self {
        self.log_x = true;
        self
    }
    pub fn with(mut self, s: Series) -> Self {
        self.series.push(s);
        self
    }
}

/// Twelve distinct colours (the work-precision diagram has twelve curves: three integrators by
/// four stabilisations).
const COLORS: [RGBColor; 12] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(0, 0, 0),
    RGBColor(255, 187, 120),
];

fn range(vals: impl Iterator<Item = f64>, log: bool) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in vals.filter(|v| v.is_finite() && (!log || *v > 0.0)) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return if log { (1e-16, 1.0) } else { (-1.0, 1.0) };
    }
    if log {
        let (l, h) = (lo.log10().floor(), hi.log10().ceil());
        let h = if h <= l { l + 1.0 } else { h };
        (10f64.powf(l), 10f64.powf(h))
    } else {
        let pad = if hi > lo {
            0.05 * (hi - lo)
        } else {
            0.5 * lo.abs().max(1e-12)
        };
        (lo - pad, hi + pad)
    }
}

/// Draws `panels` in a grid of `cols` columns into a PNG of `width` × `height` pixels, on its
/// own.
pub fn write_png(
    path: &Path,
    title: &str,
    panels: &[Panel],
    cols: usize,
    width: u32,
    height: u32,
) -> Result<(), String> {
    let mut out = crate::output::Outputs::new();
    write_png_to(&mut out, path, title, panels, cols, width, height)?;
    out.commit()
}

/// [`write_png`] as the file `path` of the run `out`: it appears when `out` is committed, with
/// the run's other files.
pub fn write_png_to(
    out: &mut crate::output::Outputs,
    path: &Path,
    title: &str,
    panels: &[Panel],
    cols: usize,
    width: u32,
    height: u32,
) -> Result<(), String> {
    register_font();
    let err = |e: &dyn std::fmt::Display| format!("{}: cannot draw the plot: {e}", path.display());
    // Drawn into an RGB buffer and encoded by the png crate: plotters' own encoder would
    // bring in the `image` crate (and its JPEG decoder), the largest dependency of the build.
    let mut rgb = vec![0u8; 3 * width as usize * height as usize];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (width, height)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(&e))?;
        let root = root
            .titled(title, ("sans-serif", 26))
            .map_err(|e| err(&e))?;
        let cols = cols.max(1);
        let rows = panels.len().div_ceil(cols).max(1);
        let areas = root.split_evenly((rows, cols));
        for (panel, area) in panels.iter().zip(areas.iter()) {
            draw_panel(panel, area).map_err(|e| err(&e))?;
        }
        root.present().map_err(|e| err(&e))?;
    }
    let file = out.create(path)?;
    let mut encoder = png::Encoder::new(std::io::BufWriter::new(file), width, height);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    // Per-row filter choice (as plotters' encoder through `image`): half the size of a fixed filter.
    encoder.set_adaptive_filter(png::AdaptiveFilterType::Adaptive);
    let mut writer = encoder.write_header().map_err(|e| err(&e))?;
    writer.write_image_data(&rgb).map_err(|e| err(&e))?;
    writer.finish().map_err(|e| err(&e))
}

/// A tick label: plain for moderate magnitudes, one-digit scientific otherwise; on a linear
/// axis of extent `span`, a value below `1e-9 span` is the rounding of zero.
fn tick(v: f64, span: f64) -> String {
    let a = v.abs();
    if a == 0.0 || a < 1e-9 * span {
        "0".into()
    } else if (1e-3..1e4).contains(&a) {
        let s = format!("{v:.4}");
        let s = s.trim_end_matches('0').trim_end_matches('.');
        s.to_string()
    } else {
        let s = format!("{v:.1e}");
        s.replace(".0e", "e")
    }
}

type Area<'a> = DrawingArea<BitMapBackend<'a>, plotters::coord::Shift>;

fn draw_panel(p: &Panel, area: &Area<'_>) -> Result<(), Box<dyn std::error::Error>> {
    let (x0, x1) = range(p.series.iter().flat_map(|s| s.x.iter().copied()), p.log_x);
    let (y0, y1) = range(p.series.iter().flat_map(|s| s.y.iter().copied()), p.log_y);
    let mut b = ChartBuilder::on(area);
    b.caption(&p.title, ("sans-serif", 18))
        .margin(8)
        .x_label_area_size(36)
        .y_label_area_size(70);
    macro_rules! draw {
        ($chart:expr) => {{
            let mut chart = $chart;
            chart
                .configure_mesh()
                .x_desc(p.x_label.as_str())
                .y_desc(p.y_label.as_str())
                .label_style(("sans-serif", 13))
                .axis_desc_style(("sans-serif", 14))
                .light_line_style(RGBColor(235, 235, 235))
                .x_label_formatter(&|v| tick(*v, if p.log_x { 0.0 } else { x1 - x0 }))
                .y_label_formatter(&|v| tick(*v, if p.log_y { 0.0 } else { y1 - y0 }))
                .draw()?;
            for (i, s) in p.series.iter().enumerate() {
                let color = COLORS[i % COLORS.len()];
                let style = if s.reference {
                    color.mix(0.5).stroke_width(1)
                } else {
                    color.stroke_width(2)
                };
                let pts =
                    s.x.iter()
                        .zip(&s.y)
                        .filter(|(x, y)| {
                            x.is_finite()
                                && y.is_finite()
                                && (!p.log_y || **y > 0.0)
                                && (!p.log_x || **x > 0.0)
                        })
                        .map(|(x, y)| (*x, *y));
                if s.markers {
                    chart.draw_series(
                        pts.clone()
                            .map(|(x, y)| Circle::new((x, y), 3, color.filled())),
                    )?;
                }
                chart
                    .draw_series(LineSeries::new(pts, style))?
                    .label(s.name.as_str())
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2))
                    });
            }
            if p.series.len() > 1 {
                chart
                    .configure_series_labels()
                    .background_style(WHITE.mix(0.85))
                    .border_style(RGBColor(200, 200, 200))
                    .label_font(("sans-serif", 12))
                    .draw()?;
            }
        }};
    }
    match (p.log_x, p.log_y) {
        (false, false) => draw!(b.build_cartesian_2d(x0..x1, y0..y1)?),
        (false, true) => draw!(b.build_cartesian_2d(x0..x1, (y0..y1).log_scale())?),
        (true, false) => draw!(b.build_cartesian_2d((x0..x1).log_scale(), y0..y1)?),
        (true, true) => draw!(b.build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())?),
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn draws_a_png_with_linear_and_log_panels() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path();
        let t: Vec<f64> = (0..200).map(|k| k as f64 * 0.01).collect();
        let s: Vec<f64> = t.iter().map(|t| (3.0 * t).sin()).collect();
        let e: Vec<f64> = t.iter().map(|t| 1e-12 * (1.0 + 10.0 * t)).collect();
        let panels = [
            Panel::new("sine", "t [s]", "y").with(Series::new("sin 3t", t.clone(), s)),
            Panel::new("error", "t [s]", "|e| [m]")
                .log_y()
                .with(Series::new("e", t, e)),
        ];
        let path = dir.join("test.png");
        write_png(&path, "test figure", &panels, 2, 800, 400).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(&bytes[1..4], b"PNG");
        assert!(bytes.len() > 5000, "a real picture, not an empty canvas");
    }
}
