//! The caller's thread pool for the `..._parallel` entry points
//! ([`LrdExecutor`]), turned into the core's [`Executor`].

use crate::status::{LrdStatus, LrdStatus::*};
use core::ffi::c_void;
use core::sync::atomic::{AtomicBool, Ordering};
use lrdenoise_core::Executor;
use std::panic::{catch_unwind, AssertUnwindSafe};

/// One task of a parallel run: `task(task_data, index, worker)`.
pub type LrdTask = unsafe extern "C" fn(task_data: *mut c_void, index: u32, worker: u32);

/// The caller's threads, for the `..._parallel` entry points.
///
/// `for_each(pool, count, task, task_data)` must call
/// `task(task_data, i, worker)` once for every `i < count` and return when
/// every call has returned. Calls may run concurrently if each call in flight
/// passes its own `worker` in [0, `workers`) (e.g. the index of the pool's
/// thread). A sequential executor calls `task(task_data, i, 0)` for i = 0,
/// 1, ... A `for_each` that skips an index, calls one twice, or passes a
/// busy or out-of-range worker makes the entry point return a status
/// (LRD_STATUS_UNSUPPORTED, LRD_STATUS_STAGE_ORDER or LRD_STATUS_INVALID_TILE)
/// instead of racing; the output is then undefined and a history's frame
/// count is left as it was. `task` and `task_data` are valid only until that
/// `for_each` call returns: calling `task` later, or returning before every
/// call of it has returned, is undefined behaviour. `workers` = 0 returns
/// LRD_STATUS_INVALID_ARGUMENT.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct LrdExecutor {
    /// Runs the tasks; not NULL.
    pub for_each: Option<unsafe extern "C" fn(pool: *mut c_void, count: u32, task: LrdTask, task_data: *mut c_void)>,
    /// Passed to `for_each` unchanged (the caller's pool); may be NULL.
    pub pool: *mut c_void,
    /// Workers that may run at once: at least 1; the scratch size depends on it.
    pub workers: u32,
}

/// What a task call runs: the core's tile body, and a flag for a caught panic.
struct Task<'a> {
    body: &'a (dyn Fn(usize, usize) + Sync),
    panicked: &'a AtomicBool,
}

unsafe extern "C" fn run_task(task_data: *mut c_void, index: u32, worker: u32) {
    // SAFETY: `task_data` is the `Task` that `run` passed to `for_each`,
    // alive until `for_each` returns (its contract).
    let task = unsafe { &*(task_data as *const Task<'_>) };
    // a panic must not unwind into the caller's C frames
    if catch_unwind(AssertUnwindSafe(|| (task.body)(index as usize, worker as usize))).is_err() {
        task.panicked.store(true, Ordering::Relaxed);
    }
}

/// A copy of `*executor`, checked: not NULL, `for_each` set, `workers` ≥ 1.
///
/// # Safety
/// `executor` is NULL or points to a valid `LrdExecutor`.
pub(crate) unsafe fn checked(executor: *const LrdExecutor) -> Result<LrdExecutor, LrdStatus> {
    // SAFETY: the caller's contract.
    let e = unsafe { *executor.as_ref().ok_or(LRD_STATUS_NULL_POINTER)? };
    if e.for_each.is_none() {
        return Err(LRD_STATUS_NULL_POINTER);
    }
    if e.workers == 0 {
        return Err(LRD_STATUS_INVALID_ARGUMENT);
    }
    Ok(e)
}

/// Runs `f` with the core's executor over `e.for_each` (`e` from
/// [`checked`]); a panic caught in a task returns LRD_STATUS_PANIC.
///
/// # Safety
/// `e.for_each` keeps the contract of [`LrdExecutor`].
pub(crate) unsafe fn run<T>(e: &LrdExecutor, f: impl FnOnce(Executor<'_>) -> T) -> Result<T, LrdStatus> {
    let for_each_c = e.for_each.ok_or(LRD_STATUS_NULL_POINTER)?;
    let panicked = AtomicBool::new(false);
    let for_each = |count: usize, body: &(dyn Fn(usize, usize) + Sync)| {
        // more tiles than a u32 counts: none run, and the core reports the skipped tiles
        let Ok(count) = u32::try_from(count) else { return };
        let task = Task { body, panicked: &panicked };
        // SAFETY: `task` outlives the call, which returns only when every
        // task has returned (the executor's contract).
        unsafe { for_each_c(e.pool, count, run_task, &task as *const Task<'_> as *mut c_void) };
    };
    let out = f(&for_each);
    if panicked.load(Ordering::Relaxed) {
        return Err(LRD_STATUS_PANIC);
    }
    Ok(out)
}
