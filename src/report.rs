//! What a run did: one shape for every method.

/// Counts of what happened during a run (summed over tiles and calls). A
/// method leaves the counts it has no notion of at 0.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Report {
    /// Input pixels with a NaN/Inf noisy value (excluded from the fit).
    pub nonfinite_noisy: u64,
    /// Input pixels with a NaN/Inf guide value (excluded from the fit; WALR
    /// treats them as "no geometry").
    pub nonfinite_guides: u64,
    /// Output pixels whose own guides were not finite, or that had no usable
    /// sample: given a local mean (or 0 where there was none).
    pub fallback_pixels: u64,
    /// FLR, BMFR: blocks without any valid pixel.
    pub empty_blocks: u64,
    /// FLR: cells whose window held no valid pixel (output 0 there).
    pub empty_cells: u64,
    /// Coefficients dropped for rank deficiency: FLR's Cholesky pivot floor,
    /// BMFR's QR pivot test (features, summed over blocks).
    pub dropped_pivots: u64,
    /// Temporal pipelines: pixels without usable history (disocclusion,
    /// motion out of the frame; the first frame is not counted).
    pub history_rejected: u64,
    /// Noisy samples scaled down by the firefly clamp ([`crate::fireflies`]).
    pub clamped_fireflies: u64,
    /// Temporal pipelines: pixels whose motion vector was NaN/Inf or longer
    /// than twice the frame (they get no history).
    pub invalid_motion: u64,
    /// Temporal pipelines: frames taken as a camera cut (the history restarted).
    pub history_resets: u64,
    /// Temporal FLR on cell moments: pixels whose history restarted
    /// because their light changed (the lag test).
    pub light_changed: u64,
}

impl core::ops::AddAssign for Report {
    fn add_assign(&mut self, o: Report) {
        self.nonfinite_noisy += o.nonfinite_noisy;
        self.nonfinite_guides += o.nonfinite_guides;
        self.fallback_pixels += o.fallback_pixels;
        self.empty_blocks += o.empty_blocks;
        self.empty_cells += o.empty_cells;
        self.dropped_pivots += o.dropped_pivots;
        self.history_rejected += o.history_rejected;
        self.clamped_fireflies += o.clamped_fireflies;
        self.invalid_motion += o.invalid_motion;
        self.history_resets += o.history_resets;
        self.light_changed += o.light_changed;
    }
}
