//! Peak resident memory of what runs in between two points of the bench (Linux: `VmHWM`, reset through
//! `/proc/self/clear_refs`).

/// Sets the process's peak resident set back to its current size (`5` into `/proc/self/clear_refs`, Linux), so
/// that the next [`peak_rss`] is the peak of what runs in between; false where the system does not allow it.
pub fn reset_peak_rss() -> bool {
    std::fs::write("/proc/self/clear_refs", "5").is_ok()
}

/// The process's peak resident set (VmHWM in `/proc/self/status`), in bytes.
pub fn peak_rss() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// Runs `f` and returns its result with the peak resident memory while it ran (`None` if the peak cannot be
/// reset or read).
pub fn with_peak<T>(f: impl FnOnce() -> T) -> (T, Option<u64>) {
    let reset = reset_peak_rss();
    let out = f();
    (out, if reset { peak_rss() } else { None })
}
