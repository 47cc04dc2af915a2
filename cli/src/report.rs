//! `lrd report` output: report.md (tables), error-versus-runtime plot (SVG and
//! PNG, log time axis, Pareto front marked) and per-frame image strips.

use crate::evaluate::{FrameImages, Record};
use plotters::prelude::*;
use std::fmt::Write as _;
use std::path::Path;

static FONT: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");

pub fn register_font() {
    let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, FONT);
}

/// Indices of the Pareto-optimal rows: no other row is both faster and better.
pub fn pareto(rows: &[&Record], better: impl Fn(&Record, &Record) -> bool) -> Vec<usize> {
    (0..rows.len())
        .filter(|&i| {
            !(0..rows.len()).any(|j| {
                j != i && rows[j].ms <= rows[i].ms && better(rows[j], rows[i]) && (rows[j].ms < rows[i].ms || better(rows[j], rows[i]))
            })
        })
        .collect()
}

pub fn table(rows: &[Record], with_frame: bool) -> String {
    let mut s = String::new();
    if with_frame {
        s += "| frame | config | PSNR dB | SSIM | FLIP | rMSE | flicker | ms |\n|---|---|---:|---:|---:|---:|---:|---:|\n";
    } else {
        s += "| config | PSNR dB | SSIM | FLIP | rMSE | flicker | ms | flags |\n|---|---:|---:|---:|---:|---:|---:|---|\n";
    }
    for r in rows {
        let ms = if r.method == "noisy" { "–".to_string() } else { format!("{:.3}", r.ms) };
        let fl = r.flicker.map(|f| format!("{f:.4}")).unwrap_or_else(|| "–".into());
        if with_frame {
            let _ = writeln!(
                s,
                "| {} | {} | {:.2} | {:.4} | {:.4} | {:.4} | {fl} | {} |",
                r.frame, r.config, r.psnr, r.ssim, r.flip, r.rmse, ms
            );
        } else {
            let _ = writeln!(
                s,
                "| {} | {:.2} | {:.4} | {:.4} | {:.4} | {fl} | {} | `{}` |",
                r.config, r.psnr, r.ssim, r.flip, r.rmse, ms, r.flags
            );
        }
    }
    s
}

fn draw<DB: DrawingBackend>(root: DrawingArea<DB, plotters::coord::Shift>, rows: &[&Record]) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let panels = root.split_evenly((1, 2));
    let timed: Vec<&Record> = rows.iter().copied().filter(|r| r.ms > 0.0).collect();
    if timed.is_empty() {
        return Ok(());
    }
    let (tmin, tmax) = timed.iter().fold((f64::MAX, 0f64), |a, r| (a.0.min(r.ms), a.1.max(r.ms)));
    let (tmin, tmax) = (tmin / 1.6, tmax * 1.6);
    let noisy: Option<&Record> = rows.iter().copied().find(|r| r.method == "noisy" && r.config == "noisy");
    for (k, panel) in panels.iter().enumerate() {
        let metric = |r: &Record| if k == 0 { r.psnr } else { r.flip };
        let (lo, hi) = timed.iter().copied().chain(noisy).fold((f64::MAX, f64::MIN), |a, r| (a.0.min(metric(r)), a.1.max(metric(r))));
        let pad = (hi - lo).max(1e-3) * 0.1;
        let name = if k == 0 { "PSNR (dB, higher is better)" } else { "FLIP (lower is better)" };
        let mut chart = ChartBuilder::on(panel)
            .caption(format!("{name} vs time"), ("sans-serif", 18))
            .margin(12)
            .x_label_area_size(36)
            .y_label_area_size(52)
            .build_cartesian_2d((tmin..tmax).log_scale(), (lo - pad)..(hi + pad))
            .map_err(|e| e.to_string())?;
        chart
            .configure_mesh()
            .x_desc("ms per frame (log)")
            .y_desc(name)
            .label_style(("sans-serif", 12))
            .draw()
            .map_err(|e| e.to_string())?;
        if let Some(n) = noisy {
            let y = metric(n);
            chart
                .draw_series(LineSeries::new([(tmin, y), (tmax, y)], RED.mix(0.5)))
                .map_err(|e| e.to_string())?
                .label("noisy input")
                .legend(|(x, y)| PathElement::new([(x, y), (x + 14, y)], RED));
        }
        let better = |a: &Record, b: &Record| if k == 0 { a.psnr > b.psnr } else { a.flip < b.flip };
        let front = pareto(&timed, better);
        let mut pts: Vec<(f64, f64)> = front.iter().map(|&i| (timed[i].ms, metric(timed[i]))).collect();
        pts.sort_by(|a, b| a.0.total_cmp(&b.0));
        chart
            .draw_series(LineSeries::new(pts.clone(), BLUE.stroke_width(2)))
            .map_err(|e| e.to_string())?
            .label("Pareto front")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 14, y)], BLUE));
        for (i, r) in timed.iter().enumerate() {
            let on = front.contains(&i);
            let color = if r.method == "flr" { BLACK } else { GREEN };
            chart
                .draw_series(std::iter::once(Circle::new((r.ms, metric(r)), if on { 5 } else { 3 }, color.filled())))
                .map_err(|e| e.to_string())?;
            if on || timed.len() <= 8 {
                chart
                    .draw_series(std::iter::once(Text::new(r.config.clone(), (r.ms, metric(r)), ("sans-serif", 10))))
                    .map_err(|e| e.to_string())?;
            }
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .label_font(("sans-serif", 12))
            .draw()
            .map_err(|e| e.to_string())?;
    }
    root.present().map_err(|e| e.to_string())
}

/// Writes `plot.svg` and `plot.png` into `dir`.
pub fn plot(dir: &Path, rows: &[&Record]) -> Result<(), String> {
    register_font();
    let svg = dir.join("plot.svg");
    draw(SVGBackend::new(&svg, (1400, 560)).into_drawing_area(), rows)?;
    let png = dir.join("plot.png");
    draw(BitMapBackend::new(&png, (1400, 560)).into_drawing_area(), rows)?;
    Ok(())
}

fn magma(v: f32) -> [u8; 3] {
    // a short piecewise-linear magma-like ramp
    let stops = [(0.0, [0, 0, 4]), (0.25, [81, 18, 124]), (0.5, [183, 55, 121]), (0.75, [252, 137, 97]), (1.0, [252, 253, 191])];
    let v = v.clamp(0.0, 1.0);
    for w in stops.windows(2) {
        let ((a, ca), (b, cb)) = (w[0], w[1]);
        if v <= b {
            let t = (v - a) / (b - a);
            return [0, 1, 2].map(|i| (ca[i] as f32 + t * (cb[i] as f32 - ca[i] as f32)) as u8);
        }
    }
    [252, 253, 191]
}

/// One PNG per frame: top row noisy | each method | reference (tone mapped),
/// bottom row the FLIP error map of each.
pub fn strips(dir: &Path, frames: &[FrameImages]) -> Result<Vec<String>, String> {
    let mut names = vec![];
    for f in frames {
        let cols = f.rows.len() + 1;
        let (w, h) = (f.w as u32, f.h as u32);
        let mut img = image::RgbImage::new(w * cols as u32, h * 2);
        let mut put = |col: usize, row: u32, rgb: &dyn Fn(usize) -> [u8; 3]| {
            for y in 0..h {
                for x in 0..w {
                    let i = (y * w + x) as usize;
                    img.put_pixel(col as u32 * w + x, row * h + y, image::Rgb(rgb(i)));
                }
            }
        };
        for (c, (_, tm, fmap)) in f.rows.iter().enumerate() {
            put(c, 0, &|i| [0, 1, 2].map(|k| (tm[3 * i + k].clamp(0.0, 1.0) * 255.0).round() as u8));
            put(c, 1, &|i| magma(fmap[i]));
        }
        let r = &f.reference_tm;
        put(cols - 1, 0, &|i| [0, 1, 2].map(|k| (r[3 * i + k].clamp(0.0, 1.0) * 255.0).round() as u8));
        let name = format!("strip_{}.png", f.frame);
        img.save(dir.join(&name)).map_err(|e| format!("{}: {e}", dir.join(&name).display()))?;
        names.push(name);
    }
    Ok(names)
}
