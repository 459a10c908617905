//! Host simulator of the radiosity firmware (work in progress: see issue 6).

fn main() {}
