//! The `radiosity` command-line tool.

fn main() {}
