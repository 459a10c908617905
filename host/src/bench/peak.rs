//! Memory a part of the bench adds at its peak (Linux: `VmHWM` reset through `/proc/self/clear_refs`, less the
//! resident set it started from, so what the bench already holds from earlier sections does not count).

/// Sets the process's peak resident set back to its current size (`5` into `/proc/self/clear_refs`, Linux), so
/// that the next `VmHWM` is the peak of what runs in between; false where the system does not allow it.
fn reset_peak() -> bool {
    std::fs::write("/proc/self/clear_refs", "5").is_ok()
}

/// A field of `/proc/self/status` in bytes (`VmRSS`, `VmHWM`).
fn status_bytes(field: &str) -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.split(':').next() == Some(field))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// Runs `f` and returns its result with the resident memory it added at its peak: the peak resident set while
/// it ran less the resident set it started from (`None` if the system cannot reset or report them).
pub fn with_peak<T>(f: impl FnOnce() -> T) -> (T, Option<u64>) {
    let reset = reset_peak();
    let before = status_bytes("VmRSS");
    let out = f();
    let added = match (reset, before, status_bytes("VmHWM")) {
        (true, Some(before), Some(peak)) => Some(peak.saturating_sub(before)),
        _ => None,
    };
    (out, added)
}
