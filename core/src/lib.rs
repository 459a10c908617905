//! `radiosity-core`: the device side of the radiosity toolkit.
//!
//! `no_std`, no `alloc`, no `unsafe`, no clock. Everything the device runs lives here.
#![cfg_attr(not(any(test, feature = "std")), no_std)]
#![forbid(unsafe_code)]
