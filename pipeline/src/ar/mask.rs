//! The paper's overlay metric: the share of projected person points that land inside a 2D
//! person mask (SAM masks on the real rig, the simulator's see-through masks here), and a
//! reader for such masks stored as 8-bit greyscale PNG files.

use super::ProjectedPoint;
use crate::PipelineError;

/// Masks larger than this many pixels are refused before decoding (a 64 MiB budget).
const MAX_MASK_PIXELS: u64 = 1 << 26;

/// Counts the projected points whose pixel lies in the image (`in_image`) and, of those, the
/// ones whose mask pixel is set (`inside_mask`). `mask` is row-major, `width` x `height`, one
/// byte per pixel, any value > 0 meaning a person. The paper's inlier ratio is
/// `inside_mask / in_image`. A mask shorter than `width * height` counts its missing pixels as
/// unset.
pub fn mask_inlier_ratio(projected: &[ProjectedPoint], mask: &[u8], width: u32, height: u32) -> (usize, usize) {
    let (w, h) = (f64::from(width), f64::from(height));
    let mut inside = 0;
    let mut in_image = 0;
    for p in projected {
        if !((0.0..w).contains(&p.u) && (0.0..h).contains(&p.v)) {
            continue;
        }
        in_image += 1;
        let index = p.v.floor() as usize * width as usize + p.u.floor() as usize;
        if mask.get(index).is_some_and(|&m| m > 0) {
            inside += 1;
        }
    }
    (inside, in_image)
}

/// Decodes an 8-bit greyscale PNG mask: `(width, height, pixels)`, pixels row-major, one byte
/// each. Other colour types or bit depths are refused (a label mask must not be converted).
pub fn read_mask_png(bytes: &[u8]) -> Result<(u32, u32, Vec<u8>), PipelineError> {
    let bad = |reason: String| PipelineError::BadFile { format: "PNG mask", reason };
    let mut decoder = png::Decoder::new(bytes);
    decoder.set_limits(png::Limits { bytes: MAX_MASK_PIXELS as usize });
    let mut reader = decoder.read_info().map_err(|e| bad(e.to_string()))?;
    let info = reader.info();
    let (width, height) = (info.width, info.height);
    if info.color_type != png::ColorType::Grayscale || info.bit_depth != png::BitDepth::Eight {
        return Err(PipelineError::Unsupported {
            format: "PNG mask",
            what: format!("{:?} at {:?} bits (only 8-bit greyscale masks)", info.color_type, info.bit_depth),
        });
    }
    if u64::from(width) * u64::from(height) > MAX_MASK_PIXELS {
        return Err(bad(format!("{width} x {height} pixels is too large")));
    }
    let mut pixels = vec![0u8; reader.output_buffer_size()];
    let frame = reader.next_frame(&mut pixels).map_err(|e| bad(e.to_string()))?;
    // Greyscale 8-bit rows carry no padding, but trust the decoder's line size anyway.
    let line = frame.line_size;
    let w = width as usize;
    if line < w {
        return Err(bad(format!("decoded rows of {line} bytes for {w} pixels")));
    }
    let mut out = Vec::with_capacity(w * height as usize);
    for row in pixels.chunks(line).take(height as usize) {
        out.extend_from_slice(row.get(..w).ok_or_else(|| bad("short decoded row".into()))?);
    }
    if out.len() != w * height as usize {
        return Err(bad(format!("decoded {} of {} pixels", out.len(), w * height as usize)));
    }
    Ok((width, height, out))
}
