//! Counts what a corpus reaches: every file of the given folders through the fuzz exercise twice, as it is and
//! with its CRC rewritten (as `parse_crc` does), tallied by error kind (refined by the array or parameter it
//! names) plus the accepted tables; then the `TableError` kinds no file reached either way.
//!
//! Run: `cargo run --release --bin tally -- DIR...`

use std::collections::BTreeMap;

use radiosity_core::TableError;

fn main() {
    let dirs: Vec<String> = std::env::args().skip(1).collect();
    if dirs.is_empty() {
        eprintln!("usage: tally DIR...");
        std::process::exit(2);
    }
    // Per key: files as they are, and with the CRC rewritten.
    let mut counts = BTreeMap::<String, [u64; 2]>::new();
    let mut kinds = BTreeMap::<&'static str, u64>::new();
    let mut files = 0u64;
    for dir in &dirs {
        let entries = std::fs::read_dir(dir).unwrap_or_else(|e| {
            eprintln!("error: cannot read {dir}: {e}");
            std::process::exit(1)
        });
        for entry in entries.flatten() {
            let Ok(bytes) = std::fs::read(entry.path()) else { continue };
            files += 1;
            for (column, blob) in [bytes.clone(), radiosity_core_fuzz::with_crc(&bytes)].iter().enumerate() {
                let key = match radiosity_core_fuzz::exercise(blob) {
                    Some(e) => {
                        *kinds.entry(e.kind()).or_default() += 1;
                        radiosity_core_fuzz::key(&e)
                    }
                    None => "accepted".to_owned(),
                };
                counts.entry(key).or_default()[column] += 1;
            }
        }
    }
    println!("{files} files; per outcome: files as they are, and with the CRC rewritten");
    for (k, [raw, fixed]) in &counts {
        println!("{raw:>8} {fixed:>8}  {k}");
    }
    let missing: Vec<&str> = TableError::KINDS.iter().copied().filter(|k| !kinds.contains_key(k)).collect();
    println!(
        "{} of {} TableError kinds reached; not reached: {missing:?}",
        kinds.len(),
        TableError::KINDS.len()
    );
}
