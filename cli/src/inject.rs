//! Outlier injection for the robustness protocol of `docs/DATA.md`: fireflies
//! (`p` of the pixels set to `k` × the frame's mean luminance) or non-finite
//! samples (`p` NaN and `p` +Inf), in the `noisy` layer only, from a fixed seed.

use crate::exrio::ExrFrame;

/// One robustness case.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Injection {
    /// The frame as rendered.
    Clean,
    /// Each pixel with probability `p` gets all three channels set to
    /// `k` × the mean luminance of the noisy layer (taken before injection).
    Fireflies { p: f64, k: f64 },
    /// Each pixel with probability `p` becomes NaN, and with probability `p` +Inf.
    NonFinite { p: f64 },
}

/// The cases of the robustness table, in its order.
pub const CASES: [Injection; 4] = [
    Injection::Clean,
    Injection::Fireflies { p: 1e-4, k: 1000.0 },
    Injection::Fireflies { p: 1e-3, k: 100.0 },
    Injection::NonFinite { p: 1e-3 },
];

/// The seed of every injection: the same pixels for every method and peer.
pub const SEED: u64 = 0x6c72_645f_6f75_746c;

impl Injection {
    /// Short name, used in tables and file names: `clean`, `ff1e-4x1000`, `nan-inf1e-3`.
    pub fn name(&self) -> String {
        match self {
            Injection::Clean => "clean".into(),
            Injection::Fireflies { p, k } => format!("ff{p:e}x{k}"),
            Injection::NonFinite { p } => format!("nan-inf{p:e}"),
        }
    }

    /// A caption for tables: `clean`, `0.01 % × 1000`, `NaN+Inf 0.1 %`.
    pub fn caption(&self) -> String {
        match self {
            Injection::Clean => "clean".into(),
            Injection::Fireflies { p, k } => format!("{} % × {k}", p * 100.0),
            Injection::NonFinite { p } => format!("NaN + Inf, {} % each", p * 100.0),
        }
    }

    /// Parses `clean`, `fireflies:P:K` or `nonfinite:P`.
    pub fn parse(s: &str) -> Result<Self, String> {
        let parts: Vec<&str> = s.split(':').collect();
        let num = |v: &str| v.parse::<f64>().map_err(|_| format!("--inject: '{v}' is not a number"));
        let prob = |v: &str| {
            num(v).and_then(|p| if (0.0..=1.0).contains(&p) { Ok(p) } else { Err(format!("--inject: probability {p} not in [0, 1]")) })
        };
        match parts.as_slice() {
            ["clean"] => Ok(Injection::Clean),
            ["fireflies", p, k] => Ok(Injection::Fireflies { p: prob(p)?, k: num(k)? }),
            ["nonfinite", p] => Ok(Injection::NonFinite { p: prob(p)? }),
            _ => Err(format!("--inject: '{s}' is not clean, fireflies:P:K or nonfinite:P")),
        }
    }

    /// Injects into `frame`'s `noisy` layer; returns the number of pixels changed.
    /// `salt` varies the pixels between the frames of a sequence (0 for a still).
    pub fn apply(&self, frame: &mut ExrFrame, salt: u64) -> Result<usize, String> {
        if *self == Injection::Clean {
            return Ok(0);
        }
        let layer = frame.layers.get_mut("noisy").ok_or("no 'noisy' layer to inject into")?;
        if layer.planes.len() < 3 {
            return Err("'noisy' has fewer than 3 channels".into());
        }
        let n = layer.planes[0].len();
        let mut rng = SplitMix(SEED ^ salt.wrapping_mul(0x9e37_79b9_7f4a_7c15));
        let mut changed = 0;
        match *self {
            Injection::Clean => {}
            Injection::Fireflies { p, k } => {
                let finite: Vec<f64> = (0..n).map(|i| luminance(&layer.planes, i)).filter(|v| v.is_finite()).collect();
                let mean = finite.iter().sum::<f64>() / finite.len().max(1) as f64;
                let v = (k * mean) as f32;
                for i in 0..n {
                    if rng.unit() < p {
                        for c in 0..3 {
                            layer.planes[c][i] = v;
                        }
                        changed += 1;
                    }
                }
            }
            Injection::NonFinite { p } => {
                for i in 0..n {
                    let u = rng.unit();
                    let v = if u < p {
                        f32::NAN
                    } else if u < 2.0 * p {
                        f32::INFINITY
                    } else {
                        continue;
                    };
                    for c in 0..3 {
                        layer.planes[c][i] = v;
                    }
                    changed += 1;
                }
            }
        }
        Ok(changed)
    }
}

fn luminance(planes: &[Vec<f32>], i: usize) -> f64 {
    0.2126 * planes[0][i] as f64 + 0.7152 * planes[1][i] as f64 + 0.0722 * planes[2][i] as f64
}

/// SplitMix64: small, fixed and documented, so the injected pixels are the same on every machine.
struct SplitMix(u64);

impl SplitMix {
    /// Uniform in [0, 1) with 53 bits.
    fn unit(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::exrio::Layer;

    fn frame(n: usize) -> ExrFrame {
        let mut layers = std::collections::BTreeMap::new();
        layers.insert("noisy".into(), Layer { comps: vec!["R".into(), "G".into(), "B".into()], planes: vec![vec![1.0; n]; 3] });
        ExrFrame { width: n, height: 1, layers }
    }

    #[test]
    fn injects_the_protocol_values_at_about_the_rate() {
        let mut f = frame(200_000);
        let changed = Injection::Fireflies { p: 1e-3, k: 100.0 }.apply(&mut f, 0).unwrap();
        assert!((150..250).contains(&changed), "{changed}");
        let hot = f.layers["noisy"].planes[1].iter().filter(|&&v| v == 100.0).count();
        assert_eq!(hot, changed);
        let mut g = frame(200_000);
        Injection::Fireflies { p: 1e-3, k: 100.0 }.apply(&mut g, 0).unwrap();
        assert_eq!(f.layers["noisy"].planes, g.layers["noisy"].planes, "same seed, same pixels");
        let mut h = frame(200_000);
        let changed = Injection::NonFinite { p: 1e-3 }.apply(&mut h, 1).unwrap();
        let p = &h.layers["noisy"].planes[0];
        let (nan, inf) = (p.iter().filter(|v| v.is_nan()).count(), p.iter().filter(|v| v.is_infinite()).count());
        assert_eq!(nan + inf, changed);
        assert!(nan > 100 && inf > 100);
    }

    #[test]
    fn parses_and_names() {
        assert_eq!(Injection::parse("fireflies:1e-4:1000").unwrap(), CASES[1]);
        assert_eq!(Injection::parse("nonfinite:0.001").unwrap(), CASES[3]);
        assert!(Injection::parse("fireflies:2:10").is_err());
        assert_eq!(CASES[1].name(), "ff1e-4x1000");
    }
}
