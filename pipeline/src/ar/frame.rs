//! The rendered image and the few drawing primitives the overlay needs (all clipped to the
//! image: nothing drawn off-screen can index out of the buffer).

use crate::PipelineError;

/// An 8-bit RGB image, row-major, 3 bytes per pixel, no padding.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ArFrame {
    pub width: u32,
    pub height: u32,
    pub rgb: Vec<u8>,
}

impl ArFrame {
    /// A frame filled with one colour.
    pub fn filled(width: u32, height: u32, colour: [u8; 3]) -> Self {
        let rgb = colour.repeat(width as usize * height as usize);
        Self { width, height, rgb }
    }

    /// The colour at column `u`, row `v`; None outside the image.
    pub fn pixel(&self, u: u32, v: u32) -> Option<[u8; 3]> {
        let i = self.index(i64::from(u), i64::from(v))?;
        self.rgb.get(i..i + 3)?.try_into().ok()
    }

    /// The frame as a PNG file (8-bit RGB).
    pub fn to_png(&self) -> Result<Vec<u8>, PipelineError> {
        let bad = |e: png::EncodingError| PipelineError::BadFile { format: "PNG", reason: e.to_string() };
        let mut out = Vec::new();
        let mut encoder = png::Encoder::new(&mut out, self.width, self.height);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        // Fast compression: a frame is re-encoded for every display update.
        encoder.set_compression(png::Compression::Fast);
        let mut writer = encoder.write_header().map_err(bad)?;
        writer.write_image_data(&self.rgb).map_err(bad)?;
        writer.finish().map_err(bad)?;
        Ok(out)
    }

    /// Byte offset of pixel (x, y), if it is in the image.
    #[inline]
    fn index(&self, x: i64, y: i64) -> Option<usize> {
        let inside = (0..i64::from(self.width)).contains(&x) && (0..i64::from(self.height)).contains(&y);
        inside.then(|| (y as usize * self.width as usize + x as usize) * 3)
    }

    /// Sets one pixel; off-image pixels are ignored.
    #[inline]
    pub(crate) fn put(&mut self, x: i64, y: i64, colour: [u8; 3]) {
        if let Some(i) = self.index(x, y) {
            if let Some(px) = self.rgb.get_mut(i..i + 3) {
                px.copy_from_slice(&colour);
            }
        }
    }

    /// Fills a rectangle (clipped).
    pub(crate) fn fill_rect(&mut self, x: u32, y: u32, w: u32, h: u32, colour: [u8; 3]) {
        let (x1, y1) = (x.saturating_add(w).min(self.width), y.saturating_add(h).min(self.height));
        for yy in y..y1 {
            for xx in x..x1 {
                self.put(i64::from(xx), i64::from(yy), colour);
            }
        }
    }

    /// A filled disc of `radius_px` around the pixel holding continuous point (u, v); radius 0
    /// is that single pixel.
    pub(crate) fn disc(&mut self, u: f64, v: f64, radius_px: u32, colour: [u8; 3]) {
        let (cx, cy) = (u.floor() as i64, v.floor() as i64);
        let r = i64::from(radius_px.min(64));
        // r^2 + r rounds the disc's rim like a midpoint circle does.
        let r2 = r * r + r;
        for dy in -r..=r {
            for dx in -r..=r {
                if dx * dx + dy * dy <= r2 {
                    self.put(cx + dx, cy + dy, colour);
                }
            }
        }
    }

    /// A one-pixel line between two continuous pixel positions, clipped to the image first
    /// (Liang-Barsky), so an end far off-screen costs nothing.
    pub(crate) fn line(&mut self, a: (f64, f64), b: (f64, f64), colour: [u8; 3]) {
        let Some((a, b)) = clip_segment(a, b, f64::from(self.width), f64::from(self.height)) else { return };
        let (dx, dy) = (b.0 - a.0, b.1 - a.1);
        let steps = dx.abs().max(dy.abs()).ceil().max(1.0);
        // The clip keeps both ends in the image, so this is at most width + height steps.
        let n = steps as i64;
        for i in 0..=n {
            let t = i as f64 / steps;
            self.put((a.0 + dx * t).floor() as i64, (a.1 + dy * t).floor() as i64, colour);
        }
    }
}

/// The part of segment a-b inside `[0, w) x [0, h)` (a hair inside, so floors stay in range).
fn clip_segment(a: (f64, f64), b: (f64, f64), w: f64, h: f64) -> Option<((f64, f64), (f64, f64))> {
    let (x_max, y_max) = (w - 1e-6, h - 1e-6);
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (p, q) in [(-dx, a.0), (dx, x_max - a.0), (-dy, a.1), (dy, y_max - a.1)] {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
            continue;
        }
        let r = q / p;
        if p < 0.0 {
            t0 = t0.max(r);
        } else {
            t1 = t1.min(r);
        }
        if t0 > t1 {
            return None;
        }
    }
    if !(t0.is_finite() && t1.is_finite()) {
        return None;
    }
    Some(((a.0 + t0 * dx, a.1 + t0 * dy), (a.0 + t1 * dx, a.1 + t1 * dy)))
}
