//! `firmware-sim`: the radiosity device, on the host and as Cortex-M firmware under QEMU.
//!
//! - [`device`] (`no_std`): the device loop both sides run — relight scripts as frames of light-group
//!   intensities and budgets, light changes and bounded shooting through `radiosity-core`, and the trace line
//!   that must agree bit for bit. The firmware (`firmware/`, its own cargo workspace) depends on this crate
//!   with default features off and links only this module.
//! - With the `std` feature (default): [`script`] (the `*.relight.toml` format), [`sim`] (the host simulator
//!   with fixed buffers and CSV output), [`qemu`] (build the firmware, run it, parse its output, compare),
//!   [`cost`] (the instructions-per-work-unit model), [`synthetic`] (test tables, flat and hierarchical, written with core's writers).
#![cfg_attr(not(feature = "std"), no_std)]
#![forbid(unsafe_code)]

pub mod device;

#[cfg(feature = "std")]
pub mod cost;
#[cfg(feature = "std")]
pub mod qemu;
#[cfg(feature = "std")]
pub mod script;
#[cfg(feature = "std")]
pub mod sim;
#[cfg(feature = "std")]
pub mod synthetic;
