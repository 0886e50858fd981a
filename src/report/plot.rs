//! PNG plots of the report (plotters, bitmap backend). Text is drawn with ab_glyph from the
//! system's DejaVu Sans (`fonts-dejavu-core`, installed by `scripts/setup.sh`).
use std::sync::OnceLock;

use anyhow::{anyhow, Context, Result};
use plotters::prelude::*;

use ptm_report::study::{pareto, Outcome};
use ptm_report::{SwatchStudy, MODELS};

const FONT: &str = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf";

/// Registers DejaVu Sans as plotters' "sans-serif" (once per process).
pub fn register_font() -> Result<()> {
    static DONE: OnceLock<std::result::Result<(), String>> = OnceLock::new();
    DONE.get_or_init(|| {
        let bytes = std::fs::read(FONT).map_err(|e| {
            format!("{FONT}: {e}; install fonts-dejavu-core (scripts/setup.sh does)")
        })?;
        plotters::style::register_font(
            "sans-serif",
            FontStyle::Normal,
            Box::leak(bytes.into_boxed_slice()),
        )
        .map_err(|_| format!("{FONT}: not a usable TrueType font"))
    })
    .clone()
    .map_err(|e| anyhow!(e))
}

const COLORS: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
    RGBColor(255, 127, 14),
    RGBColor(23, 190, 207),
];

/// One marker per (link, uv) model, in the order of `ptm_report::MODELS`: identity link hollow
/// circle (projected) or cross (hemispherical); logistic link filled triangle (projected) or
/// filled circle (hemispherical, `ptm fit`'s default).
fn marker<'a, C: 'static + Clone>(
    model: usize,
    at: C,
    color: RGBColor,
) -> DynElement<'static, BitMapBackend<'a>, C> {
    match model {
        0 => Circle::new(at, 4, color.stroke_width(2)).into_dyn(),
        1 => Cross::new(at, 4, color.stroke_width(2)).into_dyn(),
        2 => TriangleMarker::new(at, 6, color.filled()).into_dyn(),
        _ => Circle::new(at, 5, color.filled()).into_dyn(),
    }
}

/// Scatter (log time, linear error) of RMS error of K against bake + fit seconds: one colour per
/// swatch, one marker per (link, uv) model; each swatch's Pareto front over every setting is the
/// solid line, the front of the plain PTM alone (identity, projected) the dashed one. Returns
/// the PNG's bytes.
pub fn error_vs_time(series: &[SwatchStudy]) -> Result<Vec<u8>> {
    register_font()?;
    let pts = series.iter().flat_map(|s| s.outcomes.iter());
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, 0f64, f64::MAX, 0f64);
    for o in pts {
        x0 = x0.min(o.seconds());
        x1 = x1.max(o.seconds());
        y0 = y0.min(o.errors.rms);
        y1 = y1.max(o.errors.rms);
    }
    if x1 <= 0.0 || y1 <= 0.0 {
        return Err(anyhow!("nothing to plot"));
    }
    let (x0, x1) = ((x0 * 0.7).max(1e-4), x1 * 1.4);
    let (y0, y1) = (y0 * 0.9, y1 * 1.1);
    let model_of = |o: &Outcome| {
        MODELS
            .iter()
            .position(|&m| m == (o.setting.link, o.setting.uv))
            .unwrap_or(0)
    };
    let size = (1040u32, 680u32);
    let mut rgb = vec![0u8; size.0 as usize * size.1 as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, size).into_drawing_area();
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(
                "Error of K on held-out lights against bake + fit time",
                ("sans-serif", 22),
            )
            .margin(14)
            .x_label_area_size(44)
            .y_label_area_size(64)
            .build_cartesian_2d((x0..x1).log_scale(), y0..y1)?;
        chart
            .configure_mesh()
            .x_desc("bake + fit seconds (2 cores)")
            .y_desc("RMS error of K")
            .label_style(("sans-serif", 14))
            .draw()?;
        for (si, study) in series.iter().enumerate() {
            let (name, outcomes) = (&study.name, &study.outcomes);
            let color = COLORS[si % COLORS.len()];
            chart
                .draw_series(
                    outcomes
                        .iter()
                        .map(|o| marker(model_of(o), (o.seconds(), o.errors.rms), color)),
                )?
                .label(name.clone())
                .legend(move |(x, y)| {
                    Rectangle::new([(x, y - 5), (x + 16, y + 5)], color.filled())
                });
            let line = |subset: Vec<Outcome>| -> Vec<(f64, f64)> {
                pareto(&subset)
                    .iter()
                    .map(|&i| (subset[i].seconds(), subset[i].errors.rms))
                    .collect()
            };
            chart.draw_series(LineSeries::new(
                line(outcomes.clone()),
                color.stroke_width(2),
            ))?;
            let plain: Vec<Outcome> = outcomes
                .iter()
                .filter(|o| model_of(o) == 0)
                .cloned()
                .collect();
            chart.draw_series(DashedLineSeries::new(
                line(plain),
                6,
                4,
                color.stroke_width(1),
            ))?;
        }
        let grey = RGBColor(90, 90, 90);
        for (mi, (link, uv)) in MODELS.iter().enumerate() {
            chart
                .draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())?
                .label(format!("{}, {}", link.name(), uv.name()))
                .legend(move |(x, y)| marker(mi, (x + 8, y), grey));
        }
        chart
            .draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())?
            .label("Pareto front, all settings")
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 16, y)], grey.stroke_width(2)));
        chart
            .draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())?
            .label("Pareto front, identity, projected")
            .legend(move |(x, y)| {
                EmptyElement::at((x, y))
                    + PathElement::new([(0, 0), (5, 0)], grey.stroke_width(1))
                    + PathElement::new([(10, 0), (16, 0)], grey.stroke_width(1))
            });
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 14))
            .draw()?;
        root.present()
            .context("drawing the error against time plot")?;
    }
    png_bytes(size, rgb)
}

/// The bytes of an 8-bit RGB PNG of `size` (plotters' bitmap buffer), for an atomic write.
pub fn png_bytes(size: (u32, u32), rgb: Vec<u8>) -> Result<Vec<u8>> {
    let img = image::RgbImage::from_raw(size.0, size.1, rgb)
        .context("the plot's buffer does not match its size")?;
    let mut bytes = std::io::Cursor::new(Vec::new());
    img.write_to(&mut bytes, image::ImageFormat::Png)?;
    Ok(bytes.into_inner())
}
