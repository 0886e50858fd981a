//! Twin of `shader/blit.wgsl`, the window's blit: same names, same maths. Plain arithmetic, so
//! it builds without the `window` feature and the twin test covers the file everywhere.

use crate::layout::BlitParams;
use crate::output::Image;

/// The full-screen triangle's clip-space vertex `i`: (−1, −1), (3, −1), (−1, 3).
pub fn vs_main(i: u32) -> [f32; 4] {
    let uv = [((i << 1) & 2) as f32, (i & 2) as f32];
    [uv[0] * 2.0 - 1.0, uv[1] * 2.0 - 1.0, 0.0, 1.0]
}

/// The sRGB transfer function of a linear value clamped to [0, 1].
pub fn srgb_encode(x: f32) -> f32 {
    let c = x.clamp(0.0, 1.0);
    if c <= 0.0031308 {
        return 12.92 * c;
    }
    1.055 * c.powf(1.0 / 2.4) - 0.055
}

/// The window pixel at `pos` (pixel + 0.5): the frame's nearest texel where the letterboxed
/// image covers it, black elsewhere.
pub fn fs_main(params: &BlitParams, frame: &Image, pos: [f32; 2]) -> [f32; 4] {
    let q = [
        (pos[0] - params.offset[0]) / params.fit[0],
        (pos[1] - params.offset[1]) / params.fit[1],
    ];
    if q.iter().any(|&x| !(0.0..1.0).contains(&x)) {
        return [0.0, 0.0, 0.0, 1.0];
    }
    let texel = [
        (q[0] * params.image[0]).min(params.image[0] - 1.0) as usize,
        (q[1] * params.image[1]).min(params.image[1] - 1.0) as usize,
    ];
    let px = frame.pixels[texel[1] * frame.width + texel[0]];
    let mut c = [0, 1, 2].map(|k| (px[k] * params.scale).clamp(0.0, 1.0));
    if params.encode > 0.5 {
        c = c.map(srgb_encode);
    }
    [c[0], c[1], c[2], 1.0]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn letterboxed_pixels_show_the_nearest_texel_and_bars_are_black() {
        // A 2×1 frame in a 4×4 window: the image is 4×2 at rows 1..3.
        let frame = Image {
            width: 2,
            height: 1,
            pixels: vec![[0.25, 0.5, 2.0, 1.0], [0.0, 1.0, 0.0, 1.0]],
        };
        let params = BlitParams {
            image: [2.0, 1.0],
            offset: [0.0, 1.0],
            fit: [4.0, 2.0],
            scale: 1.0,
            encode: 0.0,
        };
        assert_eq!(fs_main(&params, &frame, [0.5, 0.5]), [0.0, 0.0, 0.0, 1.0]);
        assert_eq!(fs_main(&params, &frame, [1.5, 1.5]), [0.25, 0.5, 1.0, 1.0]);
        assert_eq!(fs_main(&params, &frame, [3.5, 2.5]), [0.0, 1.0, 0.0, 1.0]);
        let encoded = fs_main(
            &BlitParams {
                encode: 1.0,
                ..params
            },
            &frame,
            [1.5, 1.5],
        );
        assert!((encoded[0] - srgb_encode(0.25)).abs() < 1e-7);
        assert!((srgb_encode(0.5) - 0.735_356_6).abs() < 1e-6);
        assert_eq!(vs_main(0), [-1.0, -1.0, 0.0, 1.0]);
        assert_eq!(vs_main(1), [3.0, -1.0, 0.0, 1.0]);
        assert_eq!(vs_main(2), [-1.0, 3.0, 0.0, 1.0]);
    }
}
