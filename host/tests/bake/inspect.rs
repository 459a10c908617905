//! `radiosity inspect` on baked tables: the counts it reports, and named errors for damaged files.

use super::*;
use radiosity_host::rgb::Rgb;

#[test]
fn inspect_reports_the_baked_counts() {
    let scene = lit_scene(5, 30, 0.4, Rgb::ONE);
    let baked = scene.bake(0.01, FfCodec::FLOAT8);
    let r = inspect(&baked.table).expect("inspect");
    assert_eq!(r.counts.patches, 30);
    assert_eq!(r.counts.materials, scene.materials.len());
    assert_eq!(r.counts.groups, 2);
    assert_eq!(r.counts.members, 3);
    assert_eq!(r.counts.entries, baked.report.nonzeros_after);
    assert_eq!(r.codec, "FLOAT8");
    assert_eq!(r.ff_bits, 8);
    assert!(r.base_solved);
    assert_eq!(r.static_emitters, 1);
    assert_eq!(
        r.groups.iter().map(|g| (g.id, g.members)).collect::<Vec<_>>(),
        [(group_id("lamp"), 2), (group_id("sun"), 1)]
    );
    assert_eq!(r.bytes, baked.report.table_bytes);
    assert_eq!(r.bytes.total, baked.table.len());
    assert_eq!(r.bytes.header + r.bytes.payload + r.bytes.crc, r.bytes.total);
    assert!(
        r.bytes.header >= 4 + 1 + 7,
        "header {} bytes: magic plus at least one byte per field",
        r.bytes.header
    );
    assert_eq!(r.row_len.max as usize, baked.capacities.max_row_len);
    let lens: Vec<usize> = (0..30).map(|i| baked.sparse.matrix.row(i).count()).collect();
    assert_eq!(r.row_len.min as usize, *lens.iter().min().unwrap());
    // Decoded row sums never exceed the true (f64) row sums of the kept entries, and are within the FLOAT8
    // bound 2^-5 (relative per entry, for entries >= max / 2^6) plus the small entries below it.
    let true_max = (0..30).map(|i| baked.sparse.matrix.row_sum(i)).fold(0.0, f64::max);
    assert!(r.row_sum.max <= true_max * (1.0 + f64::from(f32::EPSILON)));
    assert!(r.row_sum.max > 0.0);
    let text = r.to_string();
    assert!(text.contains("valid") && text.contains("FLOAT8"), "{text}");
    let json = serde_json::to_value(&r).unwrap();
    assert_eq!(json["counts"]["entries"], baked.report.nonzeros_after);
    let report_json = serde_json::to_value(&baked.report).unwrap();
    assert_eq!(report_json["nonzeros_after"], baked.report.nonzeros_after);
}

#[test]
fn inspect_rejects_truncated_and_corrupted_tables_with_context() {
    let scene = lit_scene(6, 20, 0.4, Rgb::ONE);
    let baked = scene.bake(0.0, FfCodec::FLOAT16);
    let len = baked.table.len();
    let err = inspect(&baked.table[..len - 10]).unwrap_err();
    let msg = err.to_string();
    assert!(msg.starts_with("<bytes>: invalid table: table truncated"), "{msg}");
    assert!(msg.contains(&format!("{} bytes, header implies {len}", len - 10)), "{msg}");

    let mut bad = baked.table.clone();
    bad[len / 2] ^= 0x40;
    let msg = inspect(&bad).unwrap_err().to_string();
    assert!(msg.contains("CRC mismatch"), "{msg}");

    let dir = std::env::temp_dir().join(format!("radiosity-bake-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("cut.rft");
    std::fs::write(&path, &baked.table[..3]).unwrap();
    let err = inspect_file(&path).unwrap_err();
    assert!(matches!(err, InspectError::Table { .. }));
    let msg = err.to_string();
    assert!(
        msg.starts_with(&path.display().to_string())
            && msg.contains("invalid table: table truncated inside its header"),
        "{msg}"
    );
    let missing = inspect_file(&dir.join("missing.rft")).unwrap_err().to_string();
    assert!(missing.contains("missing.rft: cannot read"), "{missing}");
    std::fs::remove_dir_all(&dir).unwrap();
}
