//! PNG plots of the report (plotters, bitmap backend). Text is drawn with ab_glyph from the
//! system's DejaVu Sans (`fonts-dejavu-core`, installed by `scripts/setup.sh`).
use std::path::Path;
use std::sync::OnceLock;

use anyhow::{anyhow, Context, Result};
use plotters::prelude::*;

use super::study::{pareto, Outcome};

const FONT: &str = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf";

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

/// Scatter (log time, linear error) of RMS error of K against bake + fit seconds, one colour per swatch, each
/// swatch's Pareto front joined by a line.
pub fn error_vs_time(path: &Path, series: &[(String, Vec<Outcome>)]) -> Result<()> {
    register_font()?;
    let pts = series.iter().flat_map(|(_, o)| o.iter());
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
    let tmp = ptm_fit::atomic::tmp_path(path).with_extension("png");
    {
        let root = BitMapBackend::new(&tmp, (960, 640)).into_drawing_area();
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
        for (si, (name, outcomes)) in series.iter().enumerate() {
            let color = COLORS[si % COLORS.len()];
            chart
                .draw_series(
                    outcomes
                        .iter()
                        .map(|o| Circle::new((o.seconds(), o.errors.rms), 4, color.filled())),
                )?
                .label(name.clone())
                .legend(move |(x, y)| Circle::new((x + 8, y), 4, color.filled()));
            let front: Vec<(f64, f64)> = pareto(outcomes)
                .iter()
                .map(|&i| (outcomes[i].seconds(), outcomes[i].errors.rms))
                .collect();
            chart.draw_series(LineSeries::new(front, color.stroke_width(2)))?;
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 14))
            .draw()?;
        root.present()
            .with_context(|| format!("writing {}", tmp.display()))?;
    }
    std::fs::rename(&tmp, path).with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}
