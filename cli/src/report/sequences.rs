//! The sequence table of `lrd eval` and `lrd report`: per sequence and
//! configuration, the mean PSNR of all frames and of the last 4, the mean
//! flicker of the last 4 frames, and the frames needed to converge (the first
//! frame from which every later frame is within 0.5 dB of the last 4's mean).
//! Where the frames carry a second reference (`Record::reference_flicker`),
//! two more columns: the flicker the reference's own noise contributes, `φ`,
//! and the method's flicker above it, `√max(F² − φ², 0)` per frame (the
//! method's and the reference's frame-to-frame noise are independent, so
//! their squares add).

use crate::evaluate::Record;

/// Frames averaged as "converged".
const LAST: usize = 4;
/// How close to the converged value a frame must stay, in dB.
const WITHIN_DB: f64 = 0.5;

/// The table (Markdown), or an empty string when no record is from a sequence.
pub fn table(records: &[Record]) -> String {
    let mut seqs: Vec<&str> = vec![];
    for r in records.iter().filter_map(|r| r.sequence.as_deref()) {
        if !seqs.contains(&r) {
            seqs.push(r);
        }
    }
    if seqs.is_empty() {
        return String::new();
    }
    let floors = records.iter().any(|r| r.sequence.is_some() && r.reference_flicker.is_some());
    let mut s = format!(
        "| sequence | config | frames | PSNR dB, all | PSNR dB, last {LAST} | flicker, last {LAST} | frames to within {WITHIN_DB} dB |"
    );
    s += if floors { " reference's flicker, last {LAST} | flicker above it, last {LAST} |\n" } else { "\n" };
    s = s.replace("{LAST}", &LAST.to_string());
    s += if floors { "|---|---|---:|---:|---:|---:|---:|---:|---:|\n" } else { "|---|---|---:|---:|---:|---:|---:|\n" };
    for seq in seqs {
        let mut configs: Vec<&str> = vec![];
        for r in records.iter().filter(|r| r.sequence.as_deref() == Some(seq) && r.method != "noisy") {
            if !configs.contains(&r.config.as_str()) {
                configs.push(&r.config);
            }
        }
        for c in configs {
            let mut rs: Vec<&Record> = records.iter().filter(|r| r.sequence.as_deref() == Some(seq) && r.config == c).collect();
            rs.sort_by(|a, b| a.frame.cmp(&b.frame));
            let psnr: Vec<f64> = rs.iter().map(|r| r.psnr).collect();
            let last = &psnr[psnr.len().saturating_sub(LAST)..];
            let (all_mean, last_mean) = (mean(&psnr), mean(last));
            let flicker: Vec<f64> = rs[rs.len().saturating_sub(LAST)..].iter().filter_map(|r| r.flicker).collect();
            let flk = if flicker.is_empty() { "–".to_string() } else { format!("{:.4}", mean(&flicker)) };
            let converged =
                (0..psnr.len()).find(|&k| psnr[k..].iter().all(|p| (p - last_mean).abs() <= WITHIN_DB)).map_or(psnr.len(), |k| k + 1);
            s += &format!("| {seq} | {c} | {} | {all_mean:.2} | {last_mean:.2} | {flk} | {converged} |", psnr.len());
            if floors {
                let lasts = &rs[rs.len().saturating_sub(LAST)..];
                let phi: Vec<f64> = lasts.iter().filter_map(|r| r.reference_flicker).collect();
                let above: Vec<f64> =
                    lasts.iter().filter_map(|r| Some((r.flicker? * r.flicker? - r.reference_flicker?.powi(2)).max(0.0).sqrt())).collect();
                let cell = |v: &[f64]| if v.is_empty() { "–".to_string() } else { format!("{:.4}", mean(v)) };
                s += &format!(" {} | {} |", cell(&phi), cell(&above));
            }
            s += "\n";
        }
    }
    s
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rec(seq: &str, frame: usize, psnr: f64) -> Record {
        Record {
            method: "m".into(),
            config: "c".into(),
            frame: format!("frame_{frame:04}"),
            psnr,
            ssim: 0.0,
            flip: 0.0,
            rmse: 0.0,
            ms: 0.0,
            threads: 1,
            width: 1,
            height: 1,
            flags: String::new(),
            flicker: (frame > 0).then_some(0.01),
            reference_flicker: None,
            inject: String::new(),
            sequence: Some(seq.into()),
            variant: None,
        }
    }

    #[test]
    fn last_four_and_convergence() {
        // 30, 32, 33, 34, 34, 34, 34: last 4 = 34; frame 3 (the 4th) is the first that stays within 0.5 dB
        let rs: Vec<Record> = [30.0, 32.0, 33.0, 34.0, 34.0, 34.0, 34.0].iter().enumerate().map(|(i, p)| rec("s", i, *p)).collect();
        let t = table(&rs);
        assert!(t.contains("| s | c | 7 | 33.00 | 34.00 | 0.0100 | 4 |\n"), "{t}");
        assert!(!t.contains("reference's flicker"), "{t}");
        assert_eq!(table(&[]), "");
    }

    /// With the reference's own flicker φ known, the flicker above it is
    /// `√(F² − φ²)` per frame (0 where F < φ), averaged over the last 4.
    #[test]
    fn flicker_above_the_reference_noise() {
        let mut rs: Vec<Record> = (0..6).map(|i| rec("s", i, 30.0)).collect();
        for r in rs.iter_mut().skip(1) {
            r.flicker = Some(0.05);
            r.reference_flicker = Some(0.03);
        }
        rs[5].reference_flicker = Some(0.06); // above F: 0
        let t = table(&rs);
        // φ: (0.03 · 3 + 0.06) / 4 = 0.0375; above: (0.04 · 3 + 0) / 4 = 0.03
        assert!(t.contains("| 0.0500 | 1 | 0.0375 | 0.0300 |"), "{t}");
        assert!(t.contains("reference's flicker, last 4 | flicker above it, last 4 |"), "{t}");
    }
}
