//! Report plots: well-formed SVG, decodable PNG, validated data.

use radiosity_host::picture::plot::{Plot, Series};

use super::{decode_png, scratch_dir};

/// Minimal XML well-formedness check: balanced, properly nested tags under one root. Returns (root name, text).
fn parse_xml(doc: &str) -> (String, String) {
    let mut stack: Vec<String> = Vec::new();
    let mut root = None;
    let mut text = String::new();
    let mut rest = doc;
    while let Some(start) = rest.find('<') {
        text.push_str(&rest[..start]);
        text.push(' ');
        rest = &rest[start..];
        if rest.starts_with("<?") {
            rest = &rest[rest.find("?>").expect("unterminated <?") + 2..];
            continue;
        }
        if rest.starts_with("<!--") {
            rest = &rest[rest.find("-->").expect("unterminated comment") + 3..];
            continue;
        }
        let end = rest.find('>').expect("unterminated tag");
        let tag = &rest[1..end];
        rest = &rest[end + 1..];
        if let Some(name) = tag.strip_prefix('/') {
            let open = stack.pop().unwrap_or_else(|| panic!("closing </{name}> without an open tag"));
            assert_eq!(open, name.trim(), "mismatched closing tag");
        } else {
            let name = tag.split_whitespace().next().unwrap_or("").trim_end_matches('/').to_string();
            assert!(!name.is_empty(), "empty tag");
            if stack.is_empty() {
                assert!(root.is_none(), "second root element <{name}>");
                root = Some(name.clone());
            }
            if !tag.ends_with('/') {
                stack.push(name);
            }
        }
    }
    assert!(stack.is_empty(), "unclosed tags {stack:?}");
    assert!(rest.trim().is_empty(), "text after the root element");
    let text = text.replace("&lt;", "<").replace("&gt;", ">").replace("&quot;", "\"").replace("&amp;", "&");
    (root.expect("no root element"), text)
}

fn sample_plots() -> Vec<(Plot, Vec<&'static str>)> {
    let series = |name: &str, c: f64, rate: f64| Series {
        name: name.into(),
        points: (0..8).map(|k| (10f64.powi(k), c * (-rate * f64::from(k)).exp())).collect(),
    };
    vec![
        (
            Plot::ErrorWork {
                title: "Cornell box: error against work".into(),
                x_label: "work units".into(),
                y_label: "relative L2 error".into(),
                series: vec![series("gathering", 0.5, 1.0), series("shooting <f32> & q8", 0.3, 1.7)],
            },
            vec!["gathering", "shooting <f32> & q8", "work units", "relative L2 error", "error against work"],
        ),
        (
            Plot::GroupedBars {
                title: "Error decomposition".into(),
                y_label: "relative L2 error".into(),
                categories: vec!["f64".into(), "q16".into(), "q8".into()],
                components: vec![
                    ("form factors".into(), vec![0.01, 0.01, 0.01]),
                    ("quantization".into(), vec![0.0, 0.002, 0.02]),
                    ("truncation".into(), vec![0.001, 0.001, 0.001]),
                ],
            },
            vec!["form factors", "quantization", "truncation", "q16", "relative L2 error"],
        ),
        (
            Plot::Histogram {
                title: "Patch sizes".into(),
                x_label: "patch area (mm^2)".into(),
                values: (0..300).map(|i| 10f64.powf(2.0 + f64::from(i % 37) / 10.0)).collect(),
                bins: 12,
            },
            vec!["patch area (mm^2)", "patches", "Patch sizes"],
        ),
    ]
}

#[test]
fn plots_are_well_formed_svg_and_decodable_png() {
    let dir = scratch_dir("plots");
    for (k, (plot, expected)) in sample_plots().into_iter().enumerate() {
        let svg = plot.to_svg(640, 420).unwrap();
        let (root, text) = parse_xml(&svg);
        assert_eq!(root, "svg");
        for e in expected {
            assert!(text.contains(e), "plot {k}: SVG text lacks {e:?}");
        }
        assert!(svg.contains("<polyline") || svg.contains("<rect"), "plot {k} draws nothing");
        let (svg_path, png_path) = plot.write(&dir.join(format!("plot{k}")), 640, 420).unwrap();
        assert_eq!(
            std::fs::read_to_string(&svg_path).unwrap(),
            svg,
            "plot {k}: the written SVG is the rendered one"
        );
        let (w, h, pixels) = decode_png(&std::fs::read(&png_path).unwrap());
        assert_eq!((w, h), (640, 420));
        // Not blank: some pixels are neither white nor black (the coloured series).
        let coloured =
            pixels.chunks_exact(3).filter(|p| p.iter().max().unwrap() - p.iter().min().unwrap() > 60).count();
        assert!(coloured > 100, "plot {k} PNG has only {coloured} coloured pixels");
    }
}

#[test]
fn plot_data_is_validated_and_histogram_counts_add_up() {
    let bad = Plot::ErrorWork {
        title: "t".into(),
        x_label: "x".into(),
        y_label: "y".into(),
        series: vec![Series { name: "s".into(), points: vec![(1.0, 0.5), (10.0, 0.0)] }],
    };
    let err = bad.to_svg(100, 100).unwrap_err();
    assert!(err.to_string().contains("series \"s\" point 1"), "{err}");
    let bars = Plot::GroupedBars {
        title: "t".into(),
        y_label: "y".into(),
        categories: vec!["a".into(), "b".into()],
        components: vec![("c".into(), vec![1.0])],
    };
    assert!(bars.validate().unwrap_err().to_string().contains("component \"c\" has 1 values for 2"));
    let values: Vec<f64> = (1..=1000).map(f64::from).collect();
    let hist = Plot::Histogram { title: "h".into(), x_label: "x".into(), values, bins: 3 };
    let (edges, counts) = hist.histogram_bins().unwrap();
    assert_eq!(counts.iter().sum::<usize>(), 1000);
    // Edges at 1, 10, 100, 1000: bins [1,10) has 9, [10,100) has 90, [100,1000] has 901 (the maximum goes last).
    assert!((edges[1] - 10.0).abs() < 1e-9 && (edges[2] - 100.0).abs() < 1e-9);
    assert_eq!(counts, vec![9, 90, 901]);
}
