//! End-to-end and cross-crate tests live in `tests/tests/`; this library only hosts shared test helpers.
