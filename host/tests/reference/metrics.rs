//! The error metrics: zero for identical answers, hand-computed values, the dark-patch floor, bad input.

use radiosity_host::input::InputError;
use radiosity_host::metrics::{compare, MetricsError, FLOOR_FRACTION};
use radiosity_host::rgb::luminance;
use radiosity_host::rgb::Rgb;

use super::EPS;

#[test]
fn identical_answers_have_zero_error() {
    let r = [Rgb::new(1.0, 2.0, 3.0), Rgb::ZERO, Rgb::new(5.0, 1.0, 0.5)];
    let report = compare(&r, &r, &[1.0, 2.0, 0.5]).unwrap();
    assert_eq!(
        (report.rel_l2, report.abs_rms, report.max_rel, report.luminance_rel_l2, report.luminance_max_rel),
        (0.0, 0.0, 0.0, 0.0, 0.0)
    );
    assert_eq!(report.patches, 3);
}

#[test]
fn known_perturbation_gives_the_hand_computed_error() {
    // Reference |r0| = |(1, 2, 2)| = 3, |r1| = |(0, 3, 4)| = 5; areas 1 and 3. Perturb patch 0 by (0.3, 0, 0.4),
    // |d0| = 0.5.
    //   relative L2  = sqrt(1 * 0.25) / sqrt(1 * 9 + 3 * 25) = 0.5 / sqrt(84)
    //   absolute RMS = sqrt(0.25 / 4) = 0.25
    //   floor        = 1e-3 * (1 * 3 + 3 * 5) / 4 = 4.5e-3 (below both patches: each is judged on its own)
    //   max relative = 0.5 / 3 at patch 0
    //   luminance: Y(d0) = 0.2126 * 0.3 + 0.0722 * 0.4 = 0.09266; Y(r0) = 0.2126 + 1.4304 + 0.1444 = 1.7874;
    //   Y(r1) = 2.1456 + 0.2888 = 2.4344; rel L2 = 0.09266 / sqrt(1.7874^2 + 3 * 2.4344^2);
    //   max rel = 0.09266 / 1.7874 at patch 0; floor_Y = 1e-3 * (1.7874 + 3 * 2.4344) / 4.
    let r = [Rgb::new(1.0, 2.0, 2.0), Rgb::new(0.0, 3.0, 4.0)];
    let b = [Rgb::new(1.3, 2.0, 2.4), Rgb::new(0.0, 3.0, 4.0)];
    let report = compare(&b, &r, &[1.0, 3.0]).unwrap();
    let expect = [
        ("rel_l2", report.rel_l2, 0.5 / 84f64.sqrt()),
        ("abs_rms", report.abs_rms, 0.25),
        ("floor", report.floor, 4.5e-3),
        ("max_rel", report.max_rel, 0.5 / 3.0),
        (
            "luminance_rel_l2",
            report.luminance_rel_l2,
            0.09266 / (1.7874f64.powi(2) + 3.0 * 2.4344f64.powi(2)).sqrt(),
        ),
        ("luminance_max_rel", report.luminance_max_rel, 0.09266 / 1.7874),
        ("luminance_floor", report.luminance_floor, 1e-3 * (1.7874 + 3.0 * 2.4344) / 4.0),
    ];
    // Each side is a handful (< 20) of roundings of numbers of order 1, and the 0.3 / 0.4 perturbation is
    // itself inexact in binary (relative 1e-16 of 2.4, i.e. ~1e-15 of 0.4); 1e-13 relative covers both.
    for (name, got, want) in expect {
        assert!((got - want).abs() <= 1e-13 * want.abs(), "{name}: got {got:e}, want {want:e}");
    }
    assert_eq!((report.max_rel_patch, report.luminance_max_rel_patch), (0, 0));
    assert!((luminance(Rgb::new(1.0, 1.0, 1.0)) - 1.0).abs() <= 2.0 * EPS, "Rec. 709 weights sum to 1");
}

#[test]
fn dark_patch_floor_behaves_as_documented() {
    // A bright patch (1000 per channel) and a dark one (1e-6 per channel), equal areas. An error of 1e-3 in
    // the dark patch's red channel is 577 times its own radiosity, but the floor is
    // 1e-3 * mean |r| = 1e-3 * (1000 + 1e-6) * sqrt(3) / 2, so the max relative error is 1e-3 / floor.
    let r = [Rgb::splat(1000.0), Rgb::splat(1e-6)];
    let b = [Rgb::splat(1000.0), Rgb::new(1e-6 + 1e-3, 1e-6, 1e-6)];
    let report = compare(&b, &r, &[1.0, 1.0]).unwrap();
    let floor = FLOOR_FRACTION * (1000.0 + 1e-6) * 3f64.sqrt() / 2.0;
    assert!((report.floor - floor).abs() <= 1e-14 * floor, "floor {:e} vs {floor:e}", report.floor);
    let d = (b[1][0] - r[1][0]).abs();
    assert!((report.max_rel - d / floor).abs() <= 1e-12 * report.max_rel, "max_rel {:e}", report.max_rel);
    assert_eq!(report.max_rel_patch, 1);
    assert!(report.max_rel < 1e-2, "the floor keeps a dark patch from dominating");

    // A patch above the floor is judged against itself: the same absolute error on a patch at 10x the floor.
    let mid = floor * 10.0 / 3f64.sqrt();
    let r = [Rgb::splat(1000.0), Rgb::splat(1e-6), Rgb::splat(mid)];
    let b = [Rgb::splat(1000.0), Rgb::splat(1e-6), Rgb::new(mid + 0.01, mid, mid)];
    let report = compare(&b, &r, &[1.0, 1.0, 1e-9]).unwrap();
    assert_eq!(report.max_rel_patch, 2);
    let own = 0.01 / (mid * 3f64.sqrt());
    assert!((report.max_rel - own).abs() <= 1e-12 * own, "max_rel {:e} vs {own:e}", report.max_rel);

    // An all-dark reference: identical answers give 0, different ones an infinite relative error, a finite
    // absolute one.
    let dark = [Rgb::ZERO; 2];
    assert_eq!(compare(&dark, &dark, &[1.0, 1.0]).unwrap().max_rel, 0.0);
    let lit = [Rgb::ZERO, Rgb::new(0.0, 2.0, 0.0)];
    let report = compare(&lit, &dark, &[1.0, 1.0]).unwrap();
    assert_eq!((report.rel_l2, report.max_rel), (f64::INFINITY, f64::INFINITY));
    assert_eq!(report.abs_rms, (4.0f64 / 2.0).sqrt());
}

#[test]
fn metrics_refuse_bad_input_and_serialize() {
    let r = [Rgb::ONE, Rgb::splat(2.0)];
    assert_eq!(
        compare(&r[..1], &r, &[1.0, 1.0]).unwrap_err(),
        MetricsError::Input(InputError::LengthMismatch { what: "device answer", expected: 2, found: 1 })
    );
    assert_eq!(
        compare(&r, &r, &[1.0]).unwrap_err(),
        MetricsError::Input(InputError::LengthMismatch { what: "area", expected: 2, found: 1 })
    );
    assert!(matches!(
        compare(&[Rgb::ONE, Rgb::new(f64::NAN, 0.0, 0.0)], &r, &[1.0, 1.0]).unwrap_err(),
        MetricsError::Input(InputError::NonFinite { what: "device answer", patch: 1, channel: 0, .. })
    ));
    assert_eq!(compare(&r, &r, &[1.0, 0.0]).unwrap_err(), MetricsError::BadArea { patch: 1, value: 0.0 });
    let report = compare(&[Rgb::ONE, Rgb::new(2.5, 2.0, 2.0)], &r, &[1.0, 1.0]).unwrap();
    let json = serde_json::to_value(&report).unwrap();
    assert_eq!(json["max_rel_patch"], 1);
    assert_eq!(json["rel_l2"].as_f64(), Some(report.rel_l2));
    let text = report.to_string();
    assert!(text.contains("relative L2") && text.contains("(patch 1, floor"), "{text}");
}
