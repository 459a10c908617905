//! The false-colour ramp, the per-patch colours, and the error scale with its legend.

use radiosity_host::picture::colormap::{lab_to_linear_srgb, patch_colour, ramp, ramp_lab, ErrorScale};
use radiosity_host::picture::encode_png;
use radiosity_host::rgb::Rgb;

use super::decode_png;

/// CIE L* of a linear sRGB colour (IEC 61966-2-1 Y row, CIE 15 lightness).
fn lightness(rgb: Rgb) -> f64 {
    let y = 0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2];
    let d: f64 = 6.0 / 29.0;
    let f = if y > d * d * d { y.cbrt() } else { y / (3.0 * d * d) + 4.0 / 29.0 };
    116.0 * f - 16.0
}

#[test]
fn false_colour_ramp_is_in_gamut_and_lightness_increases() {
    let mut previous = f64::NEG_INFINITY;
    for i in 0..=1024 {
        let t = f64::from(i) / 1024.0;
        let raw = lab_to_linear_srgb(ramp_lab(t));
        assert!(
            raw.to_array().iter().all(|c| (-1e-9..=1.0 + 1e-9).contains(c)),
            "t = {t}: out of gamut {raw:?}"
        );
        let l = lightness(ramp(t));
        // L* rises by 70 over the ramp, 70 / 1024 ~ 0.068 per step; require at least a quarter of that.
        assert!(l > previous + 0.017, "t = {t}: L* {l} after {previous}");
        // And it is the designed L*. The IEC 61966-2-1 matrix and the Y weights are given to 4 decimals, so the
        // Lab -> RGB -> Y round trip holds to ~1e-4 relative in Y, i.e. (116 / 3) * 1e-4 ~ 4e-3 in L*.
        assert!((l - ramp_lab(t)[0]).abs() < 1e-2, "t = {t}: L* {l} vs designed {}", ramp_lab(t)[0]);
        previous = l;
    }
}

#[test]
fn patch_colours_are_in_gamut_and_distinct_for_neighbours() {
    for i in 0..2000 {
        let h = (i as f64 * 2.399_963_229_728_653) % std::f64::consts::TAU;
        let l = [55.0, 65.0, 75.0][i % 3];
        let raw = lab_to_linear_srgb([l, 30.0 * h.cos(), 30.0 * h.sin()]);
        assert!(raw.to_array().iter().all(|c| (0.0..=1.0).contains(c)), "patch {i}: out of gamut {raw:?}");
        let (a, b) = (patch_colour(i), patch_colour(i + 1));
        let distance: i32 = (0..3).map(|k| (i32::from(a[k]) - i32::from(b[k])).abs()).sum();
        assert!(distance > 30, "patches {i} and {} look alike: {a:?} {b:?}", i + 1);
    }
}

#[test]
fn error_scale_and_legend() {
    let log = ErrorScale::new(1e-4, 1e-1, true).unwrap();
    assert_eq!(log.ticks(), vec![1e-4, 1e-3, 1e-2, 1e-1]);
    assert!((log.position(1e-3) - 1.0 / 3.0).abs() < 1e-12);
    assert_eq!(log.position(1e-9), 0.0);
    assert_eq!(log.position(5.0), 1.0);
    let lin = ErrorScale::new(0.0, 0.03, false).unwrap();
    // Range 0.03 / 5 = 0.006 -> the next 1-2-5 step is 0.01.
    let ticks = lin.ticks();
    assert_eq!(ticks.len(), 4, "{ticks:?}");
    for (k, t) in ticks.iter().enumerate() {
        assert!((t - 0.01 * k as f64).abs() < 1e-15, "{ticks:?}");
    }
    assert!(ErrorScale::new(0.0, 1.0, true).is_err());
    assert!(ErrorScale::new(1.0, 1.0, false).is_err());
    let json = log.legend_json("relative error");
    assert_eq!(json["ticks"].as_array().unwrap().len(), 4);

    let legend = log.legend("relative error of B", 360, 72).unwrap();
    let (w, h, pixels) = decode_png(&encode_png(&legend).unwrap());
    assert_eq!((w, h), (360, 72));
    // The bar's left end is dark violet, its right end bright yellow, read at the bar's middle row.
    let font_px = (72 / 6).clamp(10, 18);
    let (x0, x1, y) = (3 * font_px + 2, 360 - 3 * font_px - 3, (font_px + 8 + 72 - font_px - 14) / 2);
    let px = |x: i32| {
        let i = 3 * (y as usize * 360 + x as usize);
        [pixels[i], pixels[i + 1], pixels[i + 2]]
    };
    let (left, right) = (px(x0), px(x1));
    assert!(left[2] > left[1] && u32::from(left[0]) + u32::from(left[1]) < 200, "left end {left:?}");
    assert!(right[0] > 200 && right[1] > 200 && right[2] < 150, "right end {right:?}");
    // Tick labels are drawn: the strip below the bar has dark (text) pixels.
    let dark_below = (y as usize + 20..72)
        .flat_map(|yy| (0..360).map(move |xx| 3 * (yy * 360 + xx)))
        .filter(|&i| pixels[i] < 100 && pixels[i + 1] < 100 && pixels[i + 2] < 100)
        .count();
    assert!(dark_below > 30, "no tick labels drawn ({dark_below} dark pixels)");
}
