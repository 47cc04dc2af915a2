//! `lrd report` output: report.md (tables, a legend of the configuration
//! names), the error-versus-runtime plot (SVG and PNG, log time axis, one
//! colour and marker per method, Pareto front) and per-frame image strips with
//! a label on every panel.

use crate::evaluate::{FrameImages, Panel, Record};
use plotters::coord::Shift;
use plotters::element::{DynElement, IntoDynElement};
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

/// What the short configuration names of the tables, plot and strips mean.
pub const LEGEND: &str = "\
Each configuration is named `METHOD GUIDES SETTINGS`; the `flags` column gives the full `lrd denoise` flags.

- Guides: `N` normal, `D` depth, `P` position, `A` ambient occlusion (AO), `Alb` albedo, `-` none (so `NDA` = normal, depth, AO).
- `flr`: `bB` one affine model per B×B pixels (`--block`); `sS` a Gaussian window of σ = S pixels (`--sigma S`); \
`s6/12/20` the adaptive window, fits with σ 6, 12 and 20 blended per cell (the default); `boxR` a box window of radius R (`--box`); \
`-ao` the adaptive window's extra AO-free fit (`--without-ao`); `-aod` AO demodulation off (`--ao-demodulation off`), `aodC` with \
offset C; `tik` Tikhonov regularization (`--regularization tikhonov:…`); `up2`, `up4` traced at ½ or ¼ resolution and upsampled \
jointly (`--upsample`).
- `bmfr`: `bB` block size (`--block`); `kK` Wiener shrinkage κ = K (`--shrinkage`; `k0` = the paper's plain least squares; \
default 4, not shown). `bmfr-temporal` is the pipeline over a sequence (accumulation, reprojection).
- `walr`: `tT` à-trous iterations (`--iterations`); `pw-adaptive` the last two windows blended per pixel (default), `pwW` a fixed \
weight W of the previous window (`--previous-weight`), none = one window; `f16`/`f32` storage of the averages; `notrace` no edge \
tracing (`--no-tracing`). `walr-temporal` is its pipeline over a sequence.
- `flnr[…]`: the U-Net's channel widths (the bundled weights unless `--weights`).
- `[noisy4]`: run on the 4-spp input layer instead of the 1-spp `noisy` (`--input-layer noisy4`); `noisy`, `noisy4`: the inputs \
themselves, undenoised.
";

/// Whether a row ran on another input than the 1-spp frame: the 4-spp layer
/// or a subsampled frame (joint upsampling). Hollow markers in the plot.
pub fn other_input(r: &Record) -> bool {
    r.flags.contains("--input-layer") || r.flags.contains("--upsample")
}

/// The best row of each method by PSNR (1-spp input only), in first-seen order.
pub fn best_per_method(rows: &[Record]) -> Vec<&Record> {
    let mut out: Vec<&Record> = vec![];
    // the 1-spp rows; of the inputs themselves, only `noisy`
    let one_spp = |r: &&Record| !other_input(r) && (r.method != "noisy" || r.config == "noisy");
    for r in rows.iter().filter(one_spp) {
        match out.iter_mut().find(|b| b.method == r.method) {
            Some(b) if r.psnr > b.psnr => *b = r,
            Some(_) => {}
            None => out.push(r),
        }
    }
    out
}

/// Short text for the terminal: the best configuration of each method with its time.
pub fn summary(mean: &[Record]) -> String {
    let best = best_per_method(mean);
    let width = best.iter().map(|r| r.config.chars().count()).max().unwrap_or(0);
    let mut s = String::from("best configuration per method (mean PSNR over frames; median time per frame):\n");
    for r in best {
        let time = if r.method == "noisy" { "(the input)".to_string() } else { format!("{:>8.3} ms", r.ms) };
        let _ = writeln!(s, "  {:<width$}  {:>6.2} dB  {time}", r.config, r.psnr);
    }
    s
}

/// Colour and marker of a method in the plot.
#[derive(Clone, Copy, PartialEq)]
enum Shape {
    Circle,
    Square,
    Triangle,
    TriangleDown,
    Diamond,
    Cross,
}

fn style_of(method: &str, peer_index: usize) -> (RGBColor, Shape) {
    match method {
        "flr" => (RGBColor(31, 119, 180), Shape::Circle),
        "flnr" => (RGBColor(148, 103, 189), Shape::Diamond),
        "bmfr" => (RGBColor(255, 127, 14), Shape::Square),
        "bmfr-temporal" => (RGBColor(140, 86, 75), Shape::Square),
        "walr" => (RGBColor(44, 160, 44), Shape::Triangle),
        "walr-temporal" => (RGBColor(23, 190, 207), Shape::TriangleDown),
        _ => ([RGBColor(214, 39, 40), RGBColor(227, 119, 194), RGBColor(127, 127, 127), RGBColor(0, 0, 0)][peer_index % 4], Shape::Cross),
    }
}

/// A marker centred on `at` (data or pixel coordinates), 5 px in radius.
fn marker<'a, DB: DrawingBackend + 'a, C: Clone + 'a>(at: C, shape: Shape, color: RGBColor, hollow: bool) -> DynElement<'a, DB, C> {
    let fill: ShapeStyle = if hollow { color.stroke_width(2) } else { color.filled() };
    let line: ShapeStyle = color.stroke_width(2);
    let poly = |p: Vec<(i32, i32)>| -> DynElement<'a, DB, C> {
        if hollow {
            let mut closed = p.clone();
            closed.push(p[0]);
            (EmptyElement::at(at.clone()) + PathElement::new(closed, line)).into_dyn()
        } else {
            (EmptyElement::at(at.clone()) + Polygon::new(p, fill)).into_dyn()
        }
    };
    match shape {
        Shape::Circle => (EmptyElement::at(at.clone()) + Circle::new((0, 0), 5, fill)).into_dyn(),
        Shape::Square => poly(vec![(-4, -4), (4, -4), (4, 4), (-4, 4)]),
        Shape::Triangle => poly(vec![(0, -6), (5, 4), (-5, 4)]),
        Shape::TriangleDown => poly(vec![(0, 6), (5, -4), (-5, -4)]),
        Shape::Diamond => poly(vec![(0, -6), (6, 0), (0, 6), (-6, 0)]),
        Shape::Cross => (EmptyElement::at(at.clone())
            + PathElement::new(vec![(-5, -5), (5, 5)], color.stroke_width(3))
            + PathElement::new(vec![(-5, 5), (5, -5)], color.stroke_width(3)))
        .into_dyn(),
    }
}

fn err<E: std::fmt::Debug>(e: E) -> String {
    format!("plot: {e:?}")
}

/// Methods of the plotted rows in first-seen order, each with its colour and marker.
fn method_styles(rows: &[&Record]) -> Vec<(String, RGBColor, Shape)> {
    let mut out: Vec<(String, RGBColor, Shape)> = vec![];
    let mut peers = 0;
    for r in rows {
        if !out.iter().any(|(m, _, _)| *m == r.method) {
            let (c, s) = style_of(&r.method, peers);
            if s == Shape::Cross {
                peers += 1;
            }
            out.push((r.method.clone(), c, s));
        }
    }
    out
}

fn is_peer(method: &str) -> bool {
    !crate::methods::METHODS.contains(&method)
}

fn draw<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, rows: &[&Record]) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(err)?;
    let timed: Vec<&Record> = rows.iter().copied().filter(|r| r.ms > 0.0 && r.method != "noisy").collect();
    if timed.is_empty() {
        return root.present().map_err(err);
    }
    let (plots, legend) = root.split_vertically(root.dim_in_pixel().1 - 64);
    let panels = plots.split_evenly((1, 2));
    let styles = method_styles(&timed);
    let (tmin, tmax) = timed.iter().fold((f64::MAX, 0f64), |a, r| (a.0.min(r.ms), a.1.max(r.ms)));
    let (tmin, tmax) = (tmin / 1.5, tmax * 1.5);
    let noisy: Option<&Record> = rows.iter().copied().find(|r| r.method == "noisy" && r.config == "noisy");
    for (k, panel) in panels.iter().enumerate() {
        let metric = |r: &Record| if k == 0 { r.psnr } else { r.flip };
        // the methods fill the y axis; the noisy input is named in the caption
        let (lo, hi) = timed.iter().fold((f64::MAX, f64::MIN), |a, r| (a.0.min(metric(r)), a.1.max(metric(r))));
        let pad = (hi - lo).max(1e-3) * 0.08;
        let name = if k == 0 { "PSNR (dB, higher is better)" } else { "FLIP (lower is better)" };
        let caption = match noisy {
            Some(n) if k == 0 => format!("PSNR vs time (noisy input: {:.2} dB, below the axis)", n.psnr),
            Some(n) => format!("FLIP vs time (noisy input: {:.3}, above the axis)", n.flip),
            None => format!("{} vs time", if k == 0 { "PSNR" } else { "FLIP" }),
        };
        let mut chart = ChartBuilder::on(panel)
            .caption(caption, ("sans-serif", 17))
            .margin(12)
            .x_label_area_size(38)
            .y_label_area_size(56)
            .build_cartesian_2d((tmin..tmax).log_scale(), (lo - pad)..(hi + pad))
            .map_err(err)?;
        chart
            .configure_mesh()
            .x_desc("ms per frame (log scale)")
            .y_desc(name)
            .label_style(("sans-serif", 12))
            .light_line_style(RGBColor(235, 235, 235))
            .draw()
            .map_err(err)?;
        let better = |a: &Record, b: &Record| if k == 0 { a.psnr > b.psnr } else { a.flip < b.flip };
        // the front of the configurations on the 1-spp frame (another input is another problem)
        let same: Vec<&Record> = timed.iter().copied().filter(|r| !other_input(r)).collect();
        let front: Vec<&Record> = pareto(&same, better).into_iter().map(|i| same[i]).collect();
        let mut pts: Vec<(f64, f64)> = front.iter().map(|r| (r.ms, metric(r))).collect();
        pts.sort_by(|a, b| a.0.total_cmp(&b.0));
        // a staircase: each front point holds until the next, faster-and-worse one
        let mut stairs = vec![];
        for (i, p) in pts.iter().enumerate() {
            if i > 0 {
                stairs.push((p.0, pts[i - 1].1));
            }
            stairs.push(*p);
        }
        chart.draw_series(LineSeries::new(stairs, RGBColor(90, 90, 90).stroke_width(1))).map_err(err)?;
        let area = chart.plotting_area();
        for (m, color, shape) in &styles {
            for r in timed.iter().filter(|r| &r.method == m) {
                area.draw(&marker((r.ms, metric(r)), *shape, *color, other_input(r))).map_err(err)?;
            }
        }
        // names: the Pareto-optimal configurations and every peer, each where
        // it overlaps no other name and no marker (farther off with a leader line)
        let mut taken: Vec<(i32, i32, i32, i32)> = timed
            .iter()
            .map(|r| {
                let (x, y) = chart.backend_coord(&(r.ms, metric(r)));
                (x - 6, y - 6, x + 6, y + 6)
            })
            .collect();
        let style = ("sans-serif", 11).into_font().color(&RGBColor(40, 40, 40));
        for r in timed.iter().filter(|r| front.iter().any(|f| std::ptr::eq(*f, **r)) || is_peer(&r.method)) {
            let (x, y) = chart.backend_coord(&(r.ms, metric(r)));
            let (tw, th) = (6 * r.config.chars().count() as i32 + 4, 13);
            let overlaps = |b: &(i32, i32, i32, i32), a: &(i32, i32, i32, i32)| a.0 < b.2 && b.0 < a.2 && a.1 < b.3 && b.1 < a.3;
            let spots =
                [(8, -16), (8, 3), (-8 - tw, -16), (-8 - tw, 3), (8, -34), (8, 21), (-8 - tw, -34), (-8 - tw, 21), (8, -52), (8, 39)];
            let inside = |b: &(i32, i32, i32, i32)| {
                let ((x0, y0), (x1, y1)) = (
                    panel.get_base_pixel(),
                    (panel.get_base_pixel().0 + panel.dim_in_pixel().0 as i32, panel.get_base_pixel().1 + panel.dim_in_pixel().1 as i32),
                );
                b.0 >= x0 && b.2 <= x1 && b.1 >= y0 + 30 && b.3 <= y1
            };
            let spot = spots
                .iter()
                .map(|(dx, dy)| (x + dx, y + dy, x + dx + tw, y + dy + th))
                .find(|b| inside(b) && !taken.iter().any(|t| overlaps(t, b)))
                .unwrap_or((x + 8, y - 16, x + 8 + tw, y - 3));
            if (spot.1 - y).abs() > 20 {
                let ly = if spot.1 < y { spot.3 } else { spot.1 };
                root.draw(&PathElement::new(vec![(x, y), (spot.0 + 2, ly)], RGBColor(150, 150, 150))).map_err(err)?;
            }
            root.draw(&Text::new(r.config.clone(), (spot.0 + 2, spot.1), style.clone())).map_err(err)?;
            taken.push(spot);
        }
    }
    // the legend, under both panels
    legend.fill(&WHITE).map_err(err)?;
    let font = ("sans-serif", 13).into_font();
    let (mut x, y0, y1) = (70i32, 18i32, 44i32);
    for (m, color, shape) in &styles {
        let text = if is_peer(m) { format!("{m} (peer)") } else { m.clone() };
        legend.draw(&marker((x, y0), *shape, *color, false)).map_err(err)?;
        legend.draw(&Text::new(text.clone(), (x + 10, y0 - 7), font.clone())).map_err(err)?;
        x += 30 + 8 * text.chars().count() as i32;
    }
    let grey = RGBColor(90, 90, 90);
    legend.draw(&PathElement::new(vec![(70, y1 - 4), (80, y1 - 4), (80, y1 + 4), (90, y1 + 4)], grey.stroke_width(1))).map_err(err)?;
    let front = "Pareto front of the 1-spp configurations (none is both faster and better; named)";
    legend.draw(&Text::new(front, (100, y1 - 7), font.clone())).map_err(err)?;
    let x = 130 + 6 * front.chars().count() as i32;
    legend.draw(&marker((x, y1), Shape::Circle, grey, true)).map_err(err)?;
    let hollow = "hollow: another input, 4 spp (noisy4) or traced at reduced resolution and upsampled (upN)";
    legend.draw(&Text::new(hollow, (x + 10, y1 - 7), font.clone())).map_err(err)?;
    root.present().map_err(err)
}

/// Writes `plot.svg` and `plot.png` into `dir`.
pub fn plot(dir: &Path, rows: &[&Record]) -> Result<(), String> {
    register_font();
    let size = (1400, 620);
    let svg = dir.join("plot.svg");
    draw(SVGBackend::new(&svg, size).into_drawing_area(), rows)?;
    let png = dir.join("plot.png");
    draw(BitMapBackend::new(&png, size).into_drawing_area(), rows)?;
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

/// Height of the caption band above the images and above the FLIP maps.
const TOP_BAND: u32 = 50;
const MID_BAND: u32 = 22;

/// One PNG per frame: the images (tone mapped) with a caption band above
/// (configuration, PSNR), then their FLIP error maps (caption: mean FLIP);
/// the last column is the reference, with the FLIP colour scale under it.
/// `keep`: the configurations to show (every one when `None`), in the order
/// given.
pub fn strips(dir: &Path, frames: &[FrameImages], keep: Option<&[String]>) -> Result<Vec<String>, String> {
    register_font();
    let mut names = vec![];
    for f in frames {
        let shown: Vec<&Panel> = match keep {
            Some(k) => k.iter().filter_map(|c| f.rows.iter().find(|p| &p.config == c)).collect(),
            None => f.rows.iter().collect(),
        };
        let cols = shown.len() as u32 + 1;
        let (w, h) = (f.w as u32, f.h as u32);
        let (width, height) = (w * cols, TOP_BAND + h + MID_BAND + h);
        let mut img = image::RgbImage::from_pixel(width, height, image::Rgb([255, 255, 255]));
        let mut put = |col: u32, top: u32, rgb: &dyn Fn(usize) -> [u8; 3]| {
            for y in 0..h {
                for x in 0..w {
                    img.put_pixel(col * w + x, top + y, image::Rgb(rgb((y * w + x) as usize)));
                }
            }
        };
        let to8 = |v: &[f32], i: usize| [0, 1, 2].map(|k| (v[3 * i + k].clamp(0.0, 1.0) * 255.0).round() as u8);
        for (c, p) in shown.iter().enumerate() {
            put(c as u32, TOP_BAND, &|i| to8(&p.tm, i));
            put(c as u32, TOP_BAND + h + MID_BAND, &|i| magma(p.fmap[i]));
        }
        put(cols - 1, TOP_BAND, &|i| to8(&f.reference_tm, i));
        let mut raw = img.into_raw();
        {
            let area = BitMapBackend::with_buffer(&mut raw, (width, height)).into_drawing_area();
            let big = ("sans-serif", 14).into_font();
            let small = ("sans-serif", 12).into_font().color(&RGBColor(70, 70, 70));
            let text =
                |s: &str, x: u32, y: u32, font: &TextStyle| area.draw(&Text::new(s.to_string(), (x as i32 + 6, y as i32), font.clone()));
            for (c, p) in shown.iter().enumerate() {
                let x = c as u32 * w;
                let (method, rest) = p.config.split_once(' ').unwrap_or((p.config.as_str(), ""));
                text(method, x, 4, &big.clone().into()).map_err(err)?;
                text(rest, x, 20, &small.clone()).map_err(err)?;
                let q = if p.method == "noisy" { format!("PSNR {:.2} dB (the input)", p.psnr) } else { format!("PSNR {:.2} dB", p.psnr) };
                text(&q, x, 34, &small.clone()).map_err(err)?;
                text(&format!("FLIP {:.3}", p.flip), x, TOP_BAND + h + 4, &small.clone()).map_err(err)?;
            }
            let x = (cols - 1) * w;
            text("reference", x, 4, &big.clone().into()).map_err(err)?;
            text(&f.frame, x, 20, &small.clone()).map_err(err)?;
            text("FLIP error scale", x, TOP_BAND + h + 4, &small.clone()).map_err(err)?;
            // the colour scale of the FLIP maps, 0 (left) to 1 (right)
            let (bx, by, bw, bh) = (x + 16, TOP_BAND + h + MID_BAND + h / 3, w.saturating_sub(32).max(2), 24u32);
            for i in 0..bw {
                let [r, g, b] = magma(i as f32 / (bw - 1) as f32);
                let x0 = bx as i32 + i as i32;
                area.draw(&Rectangle::new([(x0, by as i32), (x0 + 1, (by + bh) as i32)], RGBColor(r, g, b).filled())).map_err(err)?;
            }
            text("0", bx - 6, by + bh + 4, &small.clone()).map_err(err)?;
            text("1", bx + bw - 10, by + bh + 4, &small.clone()).map_err(err)?;
            text("no error → large error", bx - 6, by + bh + 20, &small.clone()).map_err(err)?;
            area.present().map_err(err)?;
        }
        let img = image::RgbImage::from_raw(width, height, raw).ok_or("strip: bad buffer size")?;
        let name = format!("strip_{}.png", f.frame);
        img.save(dir.join(&name)).map_err(|e| format!("{}: {e}", dir.join(&name).display()))?;
        names.push(name);
    }
    Ok(names)
}
