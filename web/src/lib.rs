//! `radiosity-web`: the device core ([`radiosity_core`]) built for `wasm32-unknown-unknown` as it is, behind a
//! small C ABI that a web page calls (no wasm-bindgen, no JS glue beyond `WebAssembly.instantiate`).
//!
//! This is a wrapper, not a second solver: every number comes from core's [`Solver`] (f32 arithmetic, the same
//! code the host simulator and the Cortex-M firmware run), and WebAssembly's f32 arithmetic is IEEE 754, so a
//! page's radiosity agrees bit for bit with the host simulator's on the same table and the same calls
//! (`host/tests/web.rs` checks it under Node.js).
//!
//! # The ABI
//! One table per instance, held in this module's state (the wrapper owns `Vec` buffers; core allocates
//! nothing). Pointers are byte offsets into the instance's memory (`memory` export).
//!
//! 1. [`rft_table_buffer`]`(len)` reserves `len` bytes and returns their offset; the page copies the table
//!    (`.rft` bytes) there.
//! 2. [`rft_load`]`(tolerance)` parses it ([`Table::parse`]) and creates the solver at the cold start, with the
//!    convergence tolerance `tolerance` relative to the table's unit light power (as relight scripts give it,
//!    see [`unit_light_power`]). Returns 0, or a negative [`Status`]; [`rft_message`] / [`rft_message_len`]
//!    then hold the error as UTF-8 text.
//! 3. Each frame: [`rft_set_light`] / [`rft_set_reflectance`] for what the user changed (their units are
//!    outside the budget, as core documents), [`rft_step`]`(budget)` returning the work units used (never more
//!    than `budget`), [`rft_radiosity`] returning the offset of `3 * patches` f32 (W/m^2, patch order, RGB).
//! 4. Counts and defaults: [`rft_patch_count`], [`rft_group_count`], [`rft_material_count`], [`rft_group_id`],
//!    [`rft_intensity`], [`rft_table_reflectance`], [`rft_unshot`], [`rft_outcome`], [`rft_has_transfer`];
//!    [`rft_relight_transfer`] writes the transfer-basis answer instead of the solver's into the radiosity
//!    buffer.
//!
//! A second [`rft_load`] replaces the first table; the first table's bytes stay allocated (the solver borrowed
//! them for the instance's lifetime), which a page that loads one table never notices.
//!
//! # Not for native callers
//! The functions also build natively (so the workspace's lints and tests cover them), where the offsets are
//! plain addresses and mean nothing to anyone; only the WebAssembly build is meant to be called.

// `#[no_mangle]` is what exports a function from a wasm module, and the `unsafe_code` lint counts it (a
// symbol name could clash at link time; a cdylib of only these names cannot). There is no `unsafe` block.
#![allow(unsafe_code)]

use std::cell::RefCell;
use std::fmt::Write as _;

use firmware_sim::device::unit_light_power;
use radiosity_core::codec::decode_reflectance;
use radiosity_core::{relight_transfer, Config, Outcome, OwnedBuffers, Solver, Table};

/// Why a call failed: the negative numbers the functions return.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(i32)]
pub enum Status {
    /// The bytes are not a valid table ([`Table::parse`] failed).
    BadTable = -1,
    /// The solver rejected the table or the tolerance (e.g. below the arithmetic's convergence floor).
    Solver = -2,
    /// No table is loaded yet.
    NotLoaded = -3,
    /// A light group or material index out of range, or a reflectance / intensity core rejected.
    BadArgument = -4,
    /// The table has no transfer section.
    NoTransfer = -5,
}

/// The solver of the loaded table and the buffers the page reads.
struct Loaded {
    solver: Solver<'static, f32>,
    /// Radiosity of every patch, RGB, refreshed by [`rft_radiosity`] and [`rft_relight_transfer`].
    radiosity: Vec<f32>,
    /// What the last [`rft_step`] returned.
    outcome: Outcome,
}

thread_local! {
    /// The bytes the page copies the table into, before [`rft_load`].
    static STAGING: RefCell<Vec<u8>> = const { RefCell::new(Vec::new()) };
    /// The loaded table's solver.
    static LOADED: RefCell<Option<Loaded>> = const { RefCell::new(None) };
    /// The last error, as text.
    static MESSAGE: RefCell<String> = const { RefCell::new(String::new()) };
}

fn fail(status: Status, why: impl std::fmt::Display) -> i32 {
    MESSAGE.with_borrow_mut(|m| {
        m.clear();
        let _ = write!(m, "{why}");
    });
    status as i32
}

/// Runs `f` on the loaded table, or returns `none` if there is none.
fn with_loaded<T>(none: T, f: impl FnOnce(&mut Loaded) -> T) -> T {
    LOADED.with_borrow_mut(|l| l.as_mut().map_or(none, f))
}

/// Reserves `len` zeroed bytes for a table and returns their offset in memory; the page copies the table there
/// before calling [`rft_load`]. Each call replaces the previous reservation.
#[no_mangle]
pub extern "C" fn rft_table_buffer(len: u32) -> usize {
    STAGING.with_borrow_mut(|s| {
        *s = vec![0; len as usize];
        s.as_mut_ptr() as usize
    })
}

/// Parses the table placed by [`rft_table_buffer`] and creates the solver at its cold start (static base, every
/// light group at its default intensity as unshot power), with tolerance `tolerance * unit light power`.
/// Returns 0, [`Status::BadTable`] or [`Status::Solver`] (see [`rft_message`]).
#[no_mangle]
pub extern "C" fn rft_load(tolerance: f32) -> i32 {
    let bytes: &'static [u8] = Box::leak(STAGING.take().into_boxed_slice());
    let table = match Table::parse(bytes) {
        Ok(t) => t,
        Err(e) => return fail(Status::BadTable, e),
    };
    let store: &'static mut OwnedBuffers<f32> = Box::leak(Box::new(OwnedBuffers::for_table(&table)));
    let config = Config {
        tolerance: tolerance * unit_light_power(&table),
        overshoot: Config::<f32>::RECOMMENDED_OVERSHOOT,
    };
    match Solver::new(&table, store.buffers(), config) {
        Ok(solver) => {
            let radiosity = vec![0.0; 3 * table.patch_count() as usize];
            let outcome = Outcome::BudgetSpent { used: 0 };
            LOADED.set(Some(Loaded { solver, radiosity, outcome }));
            0
        }
        Err(e) => fail(Status::Solver, e),
    }
}

/// Offset of the last error's UTF-8 text (see [`rft_message_len`]).
#[no_mangle]
pub extern "C" fn rft_message() -> usize {
    MESSAGE.with_borrow(|m| m.as_ptr() as usize)
}

/// Length in bytes of the last error's text.
#[no_mangle]
pub extern "C" fn rft_message_len() -> u32 {
    MESSAGE.with_borrow(|m| m.len() as u32)
}

/// Patches of the loaded table (0 without one).
#[no_mangle]
pub extern "C" fn rft_patch_count() -> u32 {
    with_loaded(0, |l| l.solver.table().patch_count())
}

/// Light groups of the loaded table (0 without one).
#[no_mangle]
pub extern "C" fn rft_group_count() -> u32 {
    with_loaded(0, |l| l.solver.table().group_count())
}

/// Materials of the loaded table (0 without one).
#[no_mangle]
pub extern "C" fn rft_material_count() -> u32 {
    with_loaded(0, |l| l.solver.table().material_count())
}

/// Id of light group `group` (core's hash of its name, [`radiosity_core::group_id`]); 0 if out of range.
#[no_mangle]
pub extern "C" fn rft_group_id(group: u32) -> u32 {
    with_loaded(0, |l| l.solver.table().group_id(group).unwrap_or(0))
}

/// Whether the table has a transfer section (1) or not (0).
#[no_mangle]
pub extern "C" fn rft_has_transfer() -> u32 {
    with_loaded(0, |l| u32::from(l.solver.table().has_transfer()))
}

/// The solver's current intensity of light group `group`, channel `channel` (0..3); NaN if out of range.
#[no_mangle]
pub extern "C" fn rft_intensity(group: u32, channel: u32) -> f32 {
    with_loaded(f32::NAN, |l| {
        l.solver.intensity(group).and_then(|c| c.get(channel as usize).copied()).unwrap_or(f32::NAN)
    })
}

/// The table's reflectance of material `material`, channel `channel` (0..3), decoded; NaN if out of range.
#[no_mangle]
pub extern "C" fn rft_table_reflectance(material: u32, channel: u32) -> f32 {
    with_loaded(f32::NAN, |l| {
        l.solver
            .table()
            .reflectance(material)
            .and_then(|c| c.get(channel as usize).map(|&code| decode_reflectance(code).to_f32()))
            .unwrap_or(f32::NAN)
    })
}

/// Sets light group `group` to intensity `(r, g, b)` ([`Solver::set_light`]); returns the work units it cost
/// (outside any budget), or [`Status::NotLoaded`] / [`Status::BadArgument`].
#[no_mangle]
pub extern "C" fn rft_set_light(group: u32, r: f32, g: f32, b: f32) -> i32 {
    with_loaded(Status::NotLoaded as i32, |l| match l.solver.set_light(group, [r, g, b]) {
        Ok(units) => i32::try_from(units).unwrap_or(i32::MAX),
        Err(e) => fail(Status::BadArgument, e),
    })
}

/// Sets material `material`'s reflectance to `(r, g, b)` ([`Solver::set_reflectance`]); returns the work units
/// it cost (outside any budget), or [`Status::NotLoaded`] / [`Status::BadArgument`].
#[no_mangle]
pub extern "C" fn rft_set_reflectance(material: u32, r: f32, g: f32, b: f32) -> i32 {
    with_loaded(Status::NotLoaded as i32, |l| match l.solver.set_reflectance(material, [r, g, b]) {
        Ok(units) => i32::try_from(units).unwrap_or(i32::MAX),
        Err(e) => fail(Status::BadArgument, e),
    })
}

/// Shoots for at most `budget` work units ([`Solver::step`]); returns the units used (0 without a table).
#[no_mangle]
pub extern "C" fn rft_step(budget: u32) -> u32 {
    with_loaded(0, |l| {
        l.outcome = l.solver.step(budget);
        l.outcome.used()
    })
}

/// What the last [`rft_step`] returned: 0 converged, 1 budget spent, 2 no progress.
#[no_mangle]
pub extern "C" fn rft_outcome() -> u32 {
    with_loaded(1, |l| match l.outcome {
        Outcome::Converged { .. } => 0,
        Outcome::BudgetSpent { .. } => 1,
        Outcome::NoProgress { .. } => 2,
    })
}

/// Total unshot power `|r| + |g| + |b|` (power units), including a shot in flight; 0 without a table.
#[no_mangle]
pub extern "C" fn rft_unshot() -> f32 {
    with_loaded(0.0, |l| l.solver.total_unshot().iter().map(|c| c.abs()).sum())
}

/// Writes the solver's radiosity of every patch (W/m^2, RGB, patch order) into the radiosity buffer and returns
/// its offset (`3 * patches` f32); 0 without a table.
#[no_mangle]
pub extern "C" fn rft_radiosity() -> usize {
    with_loaded(0, |l| {
        for (i, out) in (0u32..).zip(l.radiosity.chunks_exact_mut(3)) {
            out.copy_from_slice(&l.solver.radiosity(i).unwrap_or([0.0; 3]));
        }
        l.radiosity.as_ptr() as usize
    })
}

/// Writes the transfer-basis answer for the solver's current intensities ([`relight_transfer`], valid for the
/// table's reflectances) into the radiosity buffer (read it at [`rft_radiosity`]'s offset without calling that
/// again, which would overwrite it); returns the work units it cost, or [`Status::NotLoaded`] /
/// [`Status::NoTransfer`].
#[no_mangle]
pub extern "C" fn rft_relight_transfer() -> i32 {
    with_loaded(Status::NotLoaded as i32, |l| {
        let table = *l.solver.table();
        if !table.has_transfer() {
            return fail(Status::NoTransfer, "the table has no transfer section");
        }
        let intensity: Vec<[f32; 3]> =
            (0..table.group_count()).map(|g| l.solver.intensity(g).unwrap_or([0.0; 3])).collect();
        let mut out = vec![[0.0f32; 3]; table.patch_count() as usize];
        match relight_transfer(&table, &intensity, &mut out) {
            Ok(units) => {
                for (dst, src) in l.radiosity.chunks_exact_mut(3).zip(&out) {
                    dst.copy_from_slice(src);
                }
                i32::try_from(units).unwrap_or(i32::MAX)
            }
            Err(e) => fail(Status::NoTransfer, e),
        }
    })
}
