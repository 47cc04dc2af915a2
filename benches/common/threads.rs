//! A plain executor for the benches that compare thread counts.

/// `f(i, worker)` for every `i < count`, `workers` scoped threads each taking a contiguous group.
pub fn run_groups(workers: usize, count: usize, f: &(dyn Fn(usize, usize) + Sync)) {
    if workers == 1 {
        (0..count).for_each(|i| f(i, 0));
        return;
    }
    let per = count.div_ceil(workers);
    std::thread::scope(|s| {
        for w in 0..workers {
            s.spawn(move || (w * per..((w + 1) * per).min(count)).for_each(|i| f(i, w)));
        }
    });
}
