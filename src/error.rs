//! Typed errors. Every size, stride, length and configuration is checked up
//! front; nothing in the library panics on bad input.

use core::fmt;

/// Which argument an [`Error`] is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Arg {
    /// The noisy input image.
    Noisy,
    /// A guide image (normal, depth, position, AO or a user channel).
    Guide,
    /// A low-resolution guide (joint denoise + upsample).
    GuideLow,
    /// The output image.
    Output,
    /// The scratch buffer.
    Scratch,
    /// The configuration.
    Config,
    /// A tile, band or stage index.
    Tile,
    /// A temporal pipeline's history buffer.
    History,
    /// Motion vectors.
    Motion,
    /// Per-pixel sample weights (`Frame::sample_weights`).
    Weights,
}

/// Everything that can go wrong. Small and `Copy`, carries the data needed
/// to say what was wrong.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Error {
    /// Width or height is zero, or too large to address.
    InvalidSize {
        /// The image with the bad size.
        arg: Arg,
        /// Its width in pixels.
        width: usize,
        /// Its height in pixels.
        height: usize,
    },
    /// An image does not have the size the denoiser was created for.
    SizeMismatch {
        /// The image with the wrong size.
        arg: Arg,
        /// The denoiser's `(width, height)`.
        expected: (usize, usize),
        /// The image's `(width, height)`.
        got: (usize, usize),
    },
    /// Offset/strides address an element past the end of the buffer
    /// (`needed` elements, `len` given).
    BufferTooSmall {
        /// The image whose buffer is too small.
        arg: Arg,
        /// Elements its offset, strides and size address.
        needed: usize,
        /// Elements in the buffer given.
        len: usize,
    },
    /// A stride is unusable (zero where it must not be, or overflows).
    InvalidStride {
        /// The image with the bad stride.
        arg: Arg,
    },
    /// Wrong number of channels for this image (e.g. a 2-channel normal).
    ChannelCount {
        /// The image with the wrong channel count.
        arg: Arg,
        /// Channels it must have.
        expected: usize,
        /// Channels it has.
        got: usize,
    },
    /// The frame lacks a guide the configuration asks for, or has one it does not.
    GuideMismatch,
    /// More guide channels than [`crate::MAX_GUIDES`].
    TooManyGuides {
        /// Guide channels given.
        got: usize,
    },
    /// A configuration value is out of range; the string names the field.
    InvalidConfig(&'static str),
    /// The scratch buffer is smaller than `scratch_len()`.
    ScratchTooSmall {
        /// Elements needed.
        needed: usize,
        /// Elements given.
        got: usize,
    },
    /// Tile/band index out of range, or a band slice of the wrong length.
    InvalidTile {
        /// The tile, band or row index given.
        index: usize,
        /// How many there are.
        count: usize,
    },
    /// This operation is not possible with these arguments (the string says why).
    Unsupported(&'static str),
    /// A tile of stage `stage` ([`crate::flr::Stage`] index) was run out of
    /// order: before the stage ahead of it completed or before the frame's
    /// prepare, a second time in one frame, with a worker that is busy, or with
    /// other arguments than the frame's prepare.
    StageOrder {
        /// The stage's [`crate::flr::Stage`] index.
        stage: u8,
        /// The tile index within the stage.
        tile: usize,
    },
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Error::InvalidSize { arg, width, height } => {
                write!(f, "{arg:?}: invalid size {width}x{height}")
            }
            Error::SizeMismatch { arg, expected, got } => {
                write!(f, "{arg:?}: size {}x{} does not match the expected {}x{}", got.0, got.1, expected.0, expected.1)
            }
            Error::BufferTooSmall { arg, needed, len } => {
                write!(f, "{arg:?}: buffer of {len} elements is too small for its layout ({needed} needed)")
            }
            Error::InvalidStride { arg } => write!(f, "{arg:?}: invalid stride"),
            Error::ChannelCount { arg, expected, got } => {
                write!(f, "{arg:?}: expected {expected} channels, got {got}")
            }
            Error::GuideMismatch => {
                write!(f, "the frame's guides do not match the configured guide set")
            }
            Error::TooManyGuides { got } => write!(f, "{got} guide channels; at most {} are supported", crate::MAX_GUIDES),
            Error::InvalidConfig(field) => write!(f, "invalid configuration: {field}"),
            Error::ScratchTooSmall { needed, got } => {
                write!(f, "scratch buffer too small: {got} given, {needed} needed")
            }
            Error::InvalidTile { index, count } => {
                write!(f, "tile {index} out of range or mis-sized (tile count {count})")
            }
            Error::Unsupported(why) => write!(f, "unsupported: {why}"),
            Error::StageOrder { stage, tile } => {
                write!(f, "stage {stage} tile {tile} run out of order (or twice, or on a busy worker, or with other arguments than its frame's prepare)")
            }
        }
    }
}

/// `core::error::Error` is `std::error::Error`: `?` converts it to
/// `Box<dyn std::error::Error>` in a `std` program, with or without `std` here.
impl core::error::Error for Error {}
