//! Tone mapping and sRGB, and the image files: PNG, Radiance HDR (RGBE) and PFM.

use radiosity_host::picture::hdr::{
    decode_hdr, decode_pfm, encode_hdr, encode_pfm, memory_path, rgbe_decode, rgbe_encode, LinearImage,
};
use radiosity_host::picture::tonemap::{srgb_decode, srgb_encode, srgb_encode_u8};
use radiosity_host::picture::{encode_png, PictureError, RgbImage, ToneMap};
use radiosity_host::rgb::luminance;
use radiosity_host::rgb::Rgb;

use super::{assert_close, decode_png};

#[test]
fn srgb_encodes_known_values() {
    assert_eq!(srgb_encode(0.0), 0.0);
    assert_eq!(srgb_encode_u8(0.0), 0);
    assert!((srgb_encode(1.0) - 1.0).abs() <= 4.0 * f64::EPSILON, "1.0 -> {}", srgb_encode(1.0));
    assert_eq!(srgb_encode_u8(1.0), 255);
    // The breakpoint belongs to the linear segment: 12.92 * 0.0031308 = 0.040449936.
    assert_eq!(srgb_encode(0.003_130_8), 12.92 * 0.003_130_8);
    // Just above it the power segment starts; IEC 61966-2-1's rounded constants make the two segments meet to
    // within about 1e-8 (a step far below one 8-bit level, 1/255).
    let above = srgb_encode(0.003_130_8 + 1e-12);
    assert!((above - 0.040_449_936).abs() < 1e-7, "power segment at the breakpoint: {above}");
    // 0.5 linear -> 0.7354 encoded -> 187.5 -> 188 (the value every sRGB table gives).
    assert!((srgb_encode(0.5) - 0.735_356_983_9).abs() < 1e-9, "0.5 -> {}", srgb_encode(0.5));
    assert_eq!(srgb_encode_u8(0.5), 188);
    assert_eq!(srgb_encode_u8(0.18), 118);
    // Out of range clamps; NaN maps to black.
    assert_eq!(srgb_encode_u8(-1.0), 0);
    assert_eq!(srgb_encode_u8(7.0), 255);
    assert_eq!(srgb_encode_u8(f64::NAN), 0);
    // decode inverts encode (both are smooth and monotone; rounding error a few ulps).
    for i in 0..=1000 {
        let x = f64::from(i) / 1000.0;
        assert!((srgb_decode(srgb_encode(x)) - x).abs() < 1e-12, "round trip at {x}");
    }
}

#[test]
fn tone_map_is_monotone_and_finite_from_0_to_1e6() {
    let tone = ToneMap::new(1.0 / 50.0, 4.0).unwrap();
    let mut previous = Rgb::splat(-1.0);
    let mut previous_y = -1.0;
    // 0, then 1e-6 .. 1e6 logarithmically (4 samples per decade of 12 decades... 100 per decade).
    let values = std::iter::once(0.0).chain((0..=1200).map(|i| 10f64.powf(-6.0 + f64::from(i) / 100.0)));
    for v in values {
        for colour in [Rgb::new(v, v, v), Rgb::new(v, 0.5 * v, 0.1 * v), Rgb::new(0.0, v, 0.0)] {
            let out = tone.map_linear(colour).unwrap();
            assert!(
                out.to_array().iter().all(|c| c.is_finite() && (0.0..=1.0).contains(c)),
                "{colour:?} -> {out:?}"
            );
        }
        let grey = tone.map_linear(Rgb::new(v, v, v)).unwrap();
        for ch in 0..3 {
            assert!(grey[ch] >= previous[ch], "not monotone at {v}: {grey:?} after {previous:?}");
        }
        let y = luminance(tone.map_linear(Rgb::new(v, 0.5 * v, 0.1 * v)).unwrap());
        assert!(y >= previous_y, "coloured luminance not monotone at {v}");
        previous = grey;
        previous_y = y;
    }
    // The white point maps to exactly white: exposed luminance 4 -> L_d = 4 (1 + 4 / 16) / 5 = 1.
    let white = tone.map_linear(Rgb::splat(200.0)).unwrap();
    assert_close(white, Rgb::ONE, 1e-12, "white point");
    assert_eq!(tone.map_srgb8(Rgb::splat(200.0)).unwrap(), [255; 3]);
    assert_eq!(tone.map_srgb8(Rgb::ZERO).unwrap(), [0; 3]);
    // Hue is kept below saturation: channel ratios survive.
    let c = tone.map_linear(Rgb::new(10.0, 5.0, 1.0)).unwrap();
    assert!((c[1] / c[0] - 0.5).abs() < 1e-12 && (c[2] / c[0] - 0.1).abs() < 1e-12, "{c:?}");
}

#[test]
fn tone_map_refuses_nan_and_infinity() {
    let tone = ToneMap::new(1.0, 4.0).unwrap();
    assert!(matches!(
        tone.map_linear(Rgb::new(0.0, f64::NAN, 1.0)),
        Err(PictureError::NonFinite { index: 1, .. })
    ));
    assert!(matches!(
        tone.map_linear(Rgb::new(f64::INFINITY, 0.0, 1.0)),
        Err(PictureError::NonFinite { index: 0, .. })
    ));
    let mut image = vec![Rgb::ONE; 6];
    image[4][2] = f64::NAN;
    let err = tone.map_image(&image, 3, 2).unwrap_err();
    assert!(matches!(err, PictureError::NonFinite { what: "pixel", index: 4, .. }), "{err}");
    assert!(err.to_string().contains("pixel 4"), "{err}");
    assert!(matches!(tone.map_image(&image, 4, 2), Err(PictureError::Invalid { .. })));
    let err = ToneMap::from_percentile(&[1.0, 2.0, f64::NAN], 0.9, 4.0).unwrap_err();
    assert!(matches!(err, PictureError::NonFinite { index: 2, .. }), "{err}");
    assert!(ToneMap::new(f64::NAN, 4.0).is_err());
    assert!(ToneMap::new(1.0, 0.5).is_err());
    assert!(ToneMap::from_percentile(&[], 0.9, 4.0).is_err());
}

#[test]
fn percentile_exposure_puts_the_percentile_on_exposed_luminance_one() {
    // Luminances 1..=100: the nearest-rank 95th percentile is 95.
    let lums: Vec<f64> = (1..=100).map(f64::from).collect();
    let tone = ToneMap::from_percentile(&lums, 0.95, 4.0).unwrap();
    assert!((tone.scale - 1.0 / 95.0).abs() < 1e-15, "scale {}", tone.scale);
    // Exposed luminance 1 displays as (1 + 1 / 16) / 2; four times the percentile is white.
    assert_close(
        tone.map_linear(Rgb::splat(95.0)).unwrap(),
        Rgb::splat(17.0 / 32.0),
        1e-12,
        "95th percentile",
    );
    assert_close(tone.map_linear(Rgb::splat(4.0 * 95.0)).unwrap(), Rgb::ONE, 1e-12, "4x the 95th percentile");
    assert!(tone.map_linear(Rgb::splat(4.0 * 94.0)).unwrap()[0] < 1.0);
    // An unlit scene has all zeros: scale 1, nothing fails.
    assert_eq!(ToneMap::from_percentile(&[0.0; 5], 0.95, 4.0).unwrap().scale, 1.0);
}

// Image files

#[test]
fn png_decodes_with_the_stated_size_and_pixels() {
    let mut image = RgbImage::new(7, 3);
    for y in 0..3 {
        for x in 0..7 {
            image.put(x, y, [(x * 30) as u8, (y * 80) as u8, 200]);
        }
    }
    let (w, h, pixels) = decode_png(&encode_png(&image).unwrap());
    assert_eq!((w, h), (7, 3));
    assert_eq!(pixels, image.pixels);
}

#[test]
fn hdr_round_trip_within_the_rgbe_quantization_step() {
    let (w, h) = (13u32, 5u32);
    let mut image = LinearImage::new(w, h);
    for (i, p) in image.pixels.iter_mut().enumerate() {
        // Magnitudes 1e-4 .. 1e4 and unequal channels.
        let m = 10f32.powf(-4.0 + 8.0 * i as f32 / (w * h) as f32);
        *p = [m, m * 0.37, m * (i % 3) as f32 * 0.5];
    }
    image.pixels[0] = [0.0; 3];
    let bytes = encode_hdr(&image).unwrap();
    let back = decode_hdr(&bytes, &memory_path()).unwrap();
    assert_eq!((back.width, back.height), (w, h));
    for (i, (a, b)) in image.pixels.iter().zip(&back.pixels).enumerate() {
        // RGBE keeps 8 mantissa bits under the shared exponent of the largest channel: writing truncates and
        // reading takes the middle of the step, so each channel is within half a step, max/256 (module docs),
        // plus f32 rounding of the decoded value.
        let max = a.iter().copied().fold(0.0f32, f32::max);
        for ch in 0..3 {
            let tol = f64::from(max) / 256.0 * (1.0 + 1e-6);
            let d = (f64::from(a[ch]) - f64::from(b[ch])).abs();
            assert!(d <= tol, "pixel {i} channel {ch}: {} -> {} (difference {d:e} > {tol:e})", a[ch], b[ch]);
        }
    }
    // Zero stays exactly zero, and a header problem is named.
    assert_eq!(back.pixels[0], [0.0; 3]);
    let bad = decode_hdr(b"P6\n", &memory_path()).unwrap_err();
    assert!(bad.to_string().contains("#?RADIANCE"), "{bad}");
    let truncated = decode_hdr(&bytes[..bytes.len() - 10], &memory_path()).unwrap_err();
    assert!(truncated.to_string().contains("scanline 4"), "{truncated}");
    // Single pixels: 1.0 encodes as mantissa 128 at exponent 1 (1 = 0.5 * 2^1).
    assert_eq!(rgbe_encode([1.0, 0.5, 0.0]), [128, 64, 0, 129]);
    assert_eq!(rgbe_decode([128, 64, 0, 129]), [128.5 / 128.0, 64.5 / 128.0, 0.5 / 128.0]);
}

#[test]
fn hdr_reader_accepts_run_length_encoded_scanlines() {
    // One 8-pixel row in the new RLE form: marker 2 2 0 8, then per channel a run of 8 equal bytes (128 + 8).
    let mut bytes = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 1 +X 8\n".to_vec();
    bytes.extend_from_slice(&[2, 2, 0, 8]);
    for value in [128u8, 64, 32] {
        bytes.extend_from_slice(&[128 + 8, value]);
    }
    // Exponent channel as literals: count 8, then 8 bytes.
    bytes.push(8);
    bytes.extend_from_slice(&[129; 8]);
    let image = decode_hdr(&bytes, &memory_path()).unwrap();
    assert_eq!(image.pixels, vec![rgbe_decode([128, 64, 32, 129]); 8]);
}

#[test]
fn pfm_round_trip_is_exact_and_bottom_up() {
    let (w, h) = (4u32, 3u32);
    let mut image = LinearImage::new(w, h);
    for (i, p) in image.pixels.iter_mut().enumerate() {
        *p = [i as f32 * 1.5e3, -(i as f32) * 0.25, 1.0 / (i as f32 + 1.0)];
    }
    let bytes = encode_pfm(&image).unwrap();
    let header = b"PF\n4 3\n-1.0\n";
    assert_eq!(&bytes[..header.len()], header);
    // The first stored pixel is the bottom-left one (row 2 from the top).
    let first = f32::from_le_bytes(bytes[header.len()..header.len() + 4].try_into().unwrap());
    assert_eq!(first, image.pixels[(2 * w) as usize][0]);
    assert_eq!(decode_pfm(&bytes, &memory_path()).unwrap(), image);
    assert!(decode_pfm(&bytes[..bytes.len() - 1], &memory_path()).is_err());
    let mut nan = image.clone();
    nan.pixels[5][1] = f32::NAN;
    assert!(matches!(encode_pfm(&nan), Err(PictureError::NonFinite { index: 5, .. })));
}
