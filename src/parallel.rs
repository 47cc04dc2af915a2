//! Running a method's independent tiles on the caller's executor: the
//! executor's contract ([`Executor`]), the sum of the tiles' reports, and
//! per-worker buffers handed out by worker index. No thread library: the
//! caller brings the threads (rayon, a job system, `std::thread::scope`).

#[cfg(any(feature = "flr", feature = "bmfr", feature = "walr", feature = "flnr"))]
use core::sync::atomic::AtomicU32;
#[cfg(any(feature = "flr", feature = "bmfr", feature = "walr", feature = "flnr"))]
use core::sync::atomic::Ordering;

#[cfg(any(feature = "flr", feature = "bmfr", feature = "walr", feature = "flnr"))]
use crate::error::Error;
#[cfg(any(feature = "flr", feature = "bmfr", feature = "walr", feature = "flnr"))]
use crate::report::Report;

/// A caller's executor: `for_each(count, f)` calls `f(i, worker)` once for
/// every `i < count` and returns when all calls have returned. Calls may run
/// concurrently when each passes its own `worker` below the worker count the
/// denoiser was given (e.g. the thread's index in a pool). A sequential
/// executor is `&|n, f| (0..n).for_each(|i| f(i, 0))`.
pub type Executor<'e> = &'e dyn Fn(usize, &(dyn Fn(usize, usize) + Sync));

/// The sum of the tiles' reports, or the first error: a spin lock over a
/// plain value (no_std has no mutex; the critical sections are a few adds).
#[cfg(any(feature = "flr", feature = "bmfr", feature = "walr", feature = "flnr"))]
pub(crate) struct ResultCell {
    lock: core::sync::atomic::AtomicBool,
    value: core::cell::UnsafeCell<Result<Report, Error>>,
}

// SAFETY: `value` is accessed only while `lock` is held.
#[cfg(any(feature = "flr", feature = "bmfr", feature = "walr", feature = "flnr"))]
unsafe impl Sync for ResultCell {}

#[cfg(any(feature = "flr", feature = "bmfr", feature = "walr", feature = "flnr"))]
impl ResultCell {
    pub(crate) fn new() -> Self {
        ResultCell { lock: core::sync::atomic::AtomicBool::new(false), value: core::cell::UnsafeCell::new(Ok(Report::default())) }
    }
    fn with<T>(&self, f: impl FnOnce(&mut Result<Report, Error>) -> T) -> T {
        while self.lock.compare_exchange_weak(false, true, Ordering::Acquire, Ordering::Relaxed).is_err() {
            core::hint::spin_loop();
        }
        // SAFETY: the lock is held.
        let t = f(unsafe { &mut *self.value.get() });
        self.lock.store(false, Ordering::Release);
        t
    }
    pub(crate) fn add(&self, r: Result<Report, Error>) {
        self.with(|v| match (v, r) {
            (Ok(sum), Ok(r)) => *sum += r,
            (v @ Ok(_), Err(e)) => *v = Err(e),
            (Err(_), _) => {}
        })
    }
    pub(crate) fn error(&self) -> Result<(), Error> {
        self.with(|v| v.map(|_| ()))
    }
    pub(crate) fn report(&self) -> Report {
        self.with(|v| v.unwrap_or_default())
    }
}

/// One run of `items` independent tiles over a caller's scratch: a bit per
/// tile (each runs once), a busy bit per worker, then `workers` buffers of
/// `len` f32. A call on a tile that has run, or on a busy worker (an executor
/// that breaks its contract), is refused instead of racing.
#[cfg(any(feature = "flr", feature = "bmfr", feature = "walr"))]
pub(crate) struct TileRun {
    base: *mut u32,
    items: usize,
    workers: usize,
    len: usize,
}

// SAFETY: a buffer is handed out only to the one call that set its worker's
// busy bit (atomically), and the bits are only ever accessed atomically.
#[cfg(any(feature = "flr", feature = "bmfr", feature = "walr"))]
unsafe impl Sync for TileRun {}

#[cfg(any(feature = "flr", feature = "bmfr", feature = "walr"))]
impl TileRun {
    /// u32 words of the bits (whole f64, so the buffers stay 8-byte aligned).
    fn header_words(items: usize, workers: usize) -> usize {
        (items.div_ceil(32) + workers.div_ceil(32)).div_ceil(2) * 2
    }

    /// f32 values of the scratch of a run with `workers` buffers of `len`.
    pub(crate) fn scratch_len(items: usize, workers: usize, len: usize) -> Option<usize> {
        workers.checked_mul(len)?.checked_add(Self::header_words(items, workers))
    }

    /// A run over `scratch` (at least [`TileRun::scratch_len`] f32, 4-byte
    /// aligned); no tile has run and every worker is idle.
    pub(crate) fn new(scratch: &mut [f32], items: usize, workers: usize, len: usize) -> Result<Self, Error> {
        if workers == 0 {
            return Err(Error::InvalidConfig("workers must be at least 1"));
        }
        let needed = Self::scratch_len(items, workers, len).ok_or(Error::InvalidConfig("workers: scratch size overflows"))?;
        if scratch.len() < needed {
            return Err(Error::ScratchTooSmall { needed, got: scratch.len() });
        }
        let run = TileRun { base: scratch.as_mut_ptr() as *mut u32, items, workers, len };
        for i in 0..Self::header_words(items, workers) {
            run.word(i).store(0, Ordering::Relaxed);
        }
        Ok(run)
    }

    fn word(&self, i: usize) -> &AtomicU32 {
        // SAFETY: `i` is below `header_words` (inside the scratch, 4-byte
        // aligned), and header words are only accessed atomically.
        unsafe { AtomicU32::from_ptr(self.base.add(i)) }
    }

    /// Runs `f` for tile `item` with worker `worker`'s buffer; refuses an
    /// index out of range, a tile that has run and a busy worker.
    pub(crate) fn run<T>(&self, item: usize, worker: usize, f: impl FnOnce(&mut [f32]) -> Result<T, Error>) -> Result<T, Error> {
        if item >= self.items {
            return Err(Error::InvalidTile { index: item, count: self.items });
        }
        if worker >= self.workers {
            return Err(Error::InvalidTile { index: worker, count: self.workers });
        }
        let (tile, tbit) = (self.word(item / 32), 1 << (item % 32));
        if tile.fetch_or(tbit, Ordering::AcqRel) & tbit != 0 {
            return Err(Error::Unsupported("the executor ran a tile twice"));
        }
        let (busy, wbit) = (self.word(self.items.div_ceil(32) + worker / 32), 1 << (worker % 32));
        if busy.fetch_or(wbit, Ordering::Acquire) & wbit != 0 {
            return Err(Error::Unsupported("the executor ran two calls on one worker at once"));
        }
        let at = Self::header_words(self.items, self.workers) + worker * self.len;
        // SAFETY: the buffer lies inside the scratch (checked in `new`), and
        // the busy bit makes this call its only user until the bit is cleared.
        let buf = unsafe { core::slice::from_raw_parts_mut((self.base as *mut f32).add(at), self.len) };
        let r = f(buf);
        busy.fetch_and(!wbit, Ordering::Release);
        r
    }

    /// Whether every tile has run (an executor that skips tiles is caught).
    pub(crate) fn all_ran(&self) -> bool {
        (0..self.items).all(|i| self.word(i / 32).load(Ordering::Acquire) & (1 << (i % 32)) != 0)
    }
}

/// One tile's work in [`run_tiles`]: `(tile, its worker's buffer)`.
#[cfg(any(feature = "flr", feature = "bmfr", feature = "walr"))]
pub(crate) type TileBody<'b> = dyn Fn(usize, &mut [f32]) -> Result<Report, Error> + Sync + 'b;

/// Runs `body(i, buffer)` once for every tile `i < tiles` on the caller's
/// executor, each call with its worker's buffer of `len` f32 (from
/// `scratch`, at least [`TileRun::scratch_len`]); sums the reports. An
/// executor that skips a tile, runs one twice or runs two calls on one
/// worker at once gets an error.
#[cfg(any(feature = "flr", feature = "bmfr", feature = "walr"))]
pub(crate) fn run_tiles(
    scratch: &mut [f32],
    tiles: usize,
    workers: usize,
    len: usize,
    for_each: Executor<'_>,
    body: &TileBody<'_>,
) -> Result<Report, Error> {
    let run = TileRun::new(scratch, tiles, workers, len)?;
    let result = ResultCell::new();
    for_each(tiles, &|t, worker| result.add(run.run(t, worker, |buf| body(t, buf))));
    result.error()?;
    if !run.all_ran() {
        return Err(Error::Unsupported("the executor skipped tiles"));
    }
    Ok(result.report())
}

/// Most bands one [`run_bands`] call takes.
#[cfg(feature = "flnr")]
pub(crate) const MAX_BANDS: usize = 64;

/// Runs `body(band)` once for every `band < bands` (at most [`MAX_BANDS`])
/// on the caller's executor, for work that needs no buffer of its own (the
/// network's layer rows). An executor that runs a band twice (the second
/// call is not run) or skips one gets an error.
#[cfg(feature = "flnr")]
pub(crate) fn run_bands(bands: usize, for_each: Executor<'_>, body: &(dyn Fn(usize) + Sync)) -> Result<(), Error> {
    use core::sync::atomic::AtomicBool;
    if bands > MAX_BANDS {
        return Err(Error::InvalidConfig("more bands than run_bands takes"));
    }
    // one bit per band (32-bit atomics: every target has them)
    let ran = [AtomicU32::new(0), AtomicU32::new(0)];
    let bit = |b: usize| (&ran[b / 32], 1u32 << (b % 32));
    let broken = AtomicBool::new(false);
    for_each(bands, &|b, _worker| {
        if b >= bands {
            broken.store(true, Ordering::Relaxed);
            return;
        }
        let (word, m) = bit(b);
        if word.fetch_or(m, Ordering::AcqRel) & m != 0 {
            broken.store(true, Ordering::Relaxed);
            return;
        }
        body(b);
    });
    if broken.load(Ordering::Relaxed) {
        return Err(Error::Unsupported("the executor ran a tile twice"));
    }
    if (0..bands).any(|b| {
        let (word, m) = bit(b);
        word.load(Ordering::Acquire) & m == 0
    }) {
        return Err(Error::Unsupported("the executor skipped tiles"));
    }
    Ok(())
}

/// A slice cut into bands of `band` elements (the last may be shorter), for
/// concurrent writers of disjoint bands.
#[cfg(any(feature = "flr", feature = "bmfr", feature = "walr"))]
pub(crate) struct Bands<'a, T> {
    ptr: *mut T,
    len: usize,
    band: usize,
    _slice: core::marker::PhantomData<&'a mut [T]>,
}

// SAFETY: a band is made only through the unsafe `get`, whose callers keep
// the bands of concurrent calls apart; the slice is borrowed mutably for 'a.
#[cfg(any(feature = "flr", feature = "bmfr", feature = "walr"))]
unsafe impl<T: Send> Sync for Bands<'_, T> {}

#[cfg(any(feature = "flr", feature = "bmfr", feature = "walr"))]
impl<'a, T> Bands<'a, T> {
    pub(crate) fn new(slice: &'a mut [T], band: usize) -> Self {
        Bands { ptr: slice.as_mut_ptr(), len: slice.len(), band, _slice: core::marker::PhantomData }
    }

    /// Band `i` (empty past the end).
    ///
    /// # Safety
    /// No other live slice made by this `Bands` is band `i`.
    #[allow(clippy::mut_from_ref)]
    pub(crate) unsafe fn get(&self, i: usize) -> &'a mut [T] {
        let a = i.saturating_mul(self.band).min(self.len);
        let b = a.saturating_add(self.band).min(self.len);
        // SAFETY: `a..b` is inside the slice, which lives for 'a; the caller
        // keeps this band to one user.
        unsafe { core::slice::from_raw_parts_mut(self.ptr.add(a), b - a) }
    }
}
