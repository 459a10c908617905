//! Fuzz target: `Table::parse` on arbitrary bytes must return (never panic), and every accessor plus a few
//! bounded solver steps on an accepted table must not panic either.
//!
//! Run: `cd core/fuzz && cargo +nightly fuzz run parse`.
#![no_main]

use libfuzzer_sys::fuzz_target;
use radiosity_core::{relight_transfer, Config, Fixed, OwnedBuffers, Solver, Table};

fuzz_target!(|data: &[u8]| {
    let Ok(t) = Table::parse(data) else { return };
    let n = t.patch_count();
    // Keep memory bounded for huge (but valid) headers: only exercise small tables fully.
    if n > 4096 || t.entry_count() > 1 << 20 {
        return;
    }
    for i in 0..=n {
        let _ = (t.area(i), t.material(i), t.base_emission(i), t.base_irradiance(i), t.row_sum(i));
        let _ = (t.slot_of(i), t.slot_patch(i), t.slot_material(i));
    }
    for g in 0..=t.group_count() {
        let _ = (t.group_id(g), t.default_intensity(g), t.group_members(g), t.transfer_exponent(g));
        let _ = (t.transfer_code(0, g), t.transfer_response(n, g));
    }
    let _ = t.fingerprint();
    if u64::from(n) * u64::from(t.group_count()) <= 1 << 20 {
        let ones = vec![[1.0f32; 3]; t.group_count() as usize];
        let mut out = vec![[0.0f32; 3]; n as usize];
        let _ = relight_transfer(&t, &ones, &mut out);
        let ones = vec![[Fixed(1 << 32); 3]; t.group_count() as usize];
        let mut out = vec![[Fixed(0); 3]; n as usize];
        let _ = relight_transfer(&t, &ones, &mut out);
    }
    // Solver buffers hold the patches with run-time state only.
    let mut store = OwnedBuffers::<f32>::for_table(&t);
    let buffers = store.buffers();
    let Ok(mut s) = Solver::new(&t, buffers, Config { tolerance: 1e-3, overshoot: 16 }) else { return };
    for _ in 0..4 {
        let o = s.step(1000);
        assert!(o.used() <= 1000);
    }
    let _ = s.set_light(0, [0.0; 3]);
    let _ = s.set_reflectance(0, [0.5; 3]);
    let o = s.step_gauss_seidel(1000);
    assert!(o.used() <= 1000);
    for i in 0..=t.patch_count() {
        let _ = (s.radiosity(i), s.power(i), s.unshot(i));
    }
});
