//! The caller-owned state of a temporal pipeline (BMFR's or WALR's).

/// The temporal state, owned by the caller: a buffer of the pipeline's
/// `history_len()` f32 and a frame counter. Keep one per sequence and
/// configuration; [`History::reset`] after a camera cut, and before a
/// history written by one configuration is continued with another (one
/// without the temporal output accumulation leaves no previous output for
/// one with it).
#[derive(Debug)]
pub struct History<'h> {
    pub(crate) data: &'h mut [f32],
    pub(crate) frames: u32,
}

impl<'h> History<'h> {
    /// Wraps a buffer (contents are ignored until a first frame is written).
    pub fn new(data: &'h mut [f32]) -> Self {
        History { data, frames: 0 }
    }
    /// Re-wraps a buffer that already holds the state after `frames` frames
    /// (for callers that keep the buffer and the count themselves, e.g. across
    /// an FFI boundary).
    pub fn resume(data: &'h mut [f32], frames: u32) -> Self {
        History { data, frames }
    }
    /// Frames accumulated so far.
    pub fn frames(&self) -> u32 {
        self.frames
    }
    /// Forget the past (camera cut).
    pub fn reset(&mut self) {
        self.frames = 0;
    }
}
