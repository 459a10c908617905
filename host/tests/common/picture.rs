//! Pictures in the checks that compare a browser's canvas with the project's render: PNG decoding and the
//! display values of the project's tone map, unrounded, over a box of radiosities.

use radiosity_host::picture::tonemap::srgb_encode;
use radiosity_host::picture::{RgbImage, ToneMap};
use radiosity_host::rgb::Rgb;

/// An 8-bit PNG (RGB or RGBA) as RGB.
pub fn decode_png(bytes: &[u8]) -> RgbImage {
    let mut decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    decoder.set_transformations(png::Transformations::EXPAND | png::Transformations::STRIP_16);
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    let channels = info.color_type.samples();
    assert!(channels == 3 || channels == 4, "{:?}", info.color_type);
    let mut out = RgbImage::new(info.width, info.height);
    for (k, px) in buf[..info.buffer_size()].chunks_exact(channels).enumerate() {
        out.pixels[3 * k..3 * k + 3].copy_from_slice(&px[..3]);
    }
    out
}

/// Display value (unrounded 8-bit sRGB scale) of linear radiosity `c` under `tone`.
pub fn display(tone: &ToneMap, c: Rgb) -> Rgb {
    tone.map_linear(c).unwrap().map(|v| 255.0 * srgb_encode(v))
}

/// Per channel, the least and the greatest display value of the radiosities in the box `[a, b]`. Every output
/// channel of the tone map is monotone in each input channel (increasing in its own: the Reinhard factor falls
/// more slowly than the channel grows; decreasing in the others, through the luminance), so the extremes lie at
/// the box's 8 corners.
pub fn display_range(tone: &ToneMap, a: Rgb, b: Rgb) -> (Rgb, Rgb) {
    let (mut lo, mut hi) = (Rgb::INFINITY, Rgb::NEG_INFINITY);
    for corner in 0..8 {
        let pick = |k: usize| if corner >> k & 1 == 0 { a[k] } else { b[k] };
        let shown = display(tone, Rgb::new(pick(0), pick(1), pick(2)));
        lo = lo.min(shown);
        hi = hi.max(shown);
    }
    (lo, hi)
}
