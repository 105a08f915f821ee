//! The AR frame on a Linux framebuffer (`/dev/fbN`), for a small display on the rig.
//!
//! Geometry comes from sysfs (`/sys/class/graphics/fbN/`: `virtual_size` "W,H",
//! `bits_per_pixel`, `stride` in bytes) or from explicit config. Pixels follow the kernel's
//! default layouts, named as DRM fourcc codes (little-endian words): 16 bpp RGB565, 24 bpp
//! RGB888 (bytes B, G, R in memory), 32 bpp XRGB8888 (bytes B, G, R, X). The frame is scaled
//! to fit with nearest-neighbour sampling, keeping its aspect ratio, centred on black, and the
//! whole visible area is written with one `pwrite` at offset 0 (no mmap: a regular file can
//! stand in for the device in tests, and a short write is an error, not a crash).

use super::error::ViewError;
use super::hub::{check_frame, SnapshotReceiver};
use super::Shutdown;
use serde::{Deserialize, Serialize};
use starc_pipeline::ar::ArFrame;
use std::fs::{File, OpenOptions};
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};
use tokio::task::JoinHandle;

/// Pixel layouts we can write.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PixelFormat {
    Rgb565,
    Rgb888,
    Xrgb8888,
}

impl PixelFormat {
    pub fn bytes_per_pixel(self) -> usize {
        match self {
            PixelFormat::Rgb565 => 2,
            PixelFormat::Rgb888 => 3,
            PixelFormat::Xrgb8888 => 4,
        }
    }

    /// One pixel in this layout, in memory order.
    pub fn encode(self, [r, g, b]: [u8; 3], out: &mut [u8]) {
        match self {
            PixelFormat::Rgb565 => {
                let v = (u16::from(r >> 3) << 11) | (u16::from(g >> 2) << 5) | u16::from(b >> 3);
                copy_into(out, &v.to_le_bytes());
            }
            PixelFormat::Rgb888 => copy_into(out, &[b, g, r]),
            PixelFormat::Xrgb8888 => copy_into(out, &[b, g, r, 0]),
        }
    }
}

fn copy_into(out: &mut [u8], bytes: &[u8]) {
    if let Some(dst) = out.get_mut(..bytes.len()) {
        dst.copy_from_slice(bytes);
    }
}

/// The visible area of a framebuffer and how its rows are laid out.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FbGeometry {
    pub width: u32,
    pub height: u32,
    pub bits_per_pixel: u32,
    /// Bytes from one row to the next (at least width * bytes per pixel).
    pub stride_bytes: u32,
}

/// Displays bigger than this are refused (a bad sysfs value must not size a huge buffer).
const MAX_SIDE_PX: u32 = 8192;

impl FbGeometry {
    /// Reads `virtual_size`, `bits_per_pixel` and `stride` from a sysfs directory such as
    /// `/sys/class/graphics/fb0`.
    pub fn from_sysfs(dir: &Path) -> Result<Self, ViewError> {
        let read = |name: &str| -> Result<String, ViewError> {
            let path = dir.join(name);
            std::fs::read_to_string(&path).map(|s| s.trim().to_string()).map_err(|e| ViewError::Framebuffer {
                path: path.clone(),
                reason: format!("reading the geometry: {e}"),
            })
        };
        let bad = |name: &str, text: &str| ViewError::Framebuffer {
            path: dir.join(name),
            reason: format!("cannot parse {text:?}"),
        };
        let size = read("virtual_size")?;
        let (w, h) = size.split_once(',').ok_or_else(|| bad("virtual_size", &size))?;
        let width = w.trim().parse().map_err(|_| bad("virtual_size", &size))?;
        let height = h.trim().parse().map_err(|_| bad("virtual_size", &size))?;
        let bpp = read("bits_per_pixel")?;
        let bits_per_pixel = bpp.parse().map_err(|_| bad("bits_per_pixel", &bpp))?;
        let stride = read("stride")?;
        let stride_bytes = stride.parse().map_err(|_| bad("stride", &stride))?;
        let g = Self { width, height, bits_per_pixel, stride_bytes };
        g.validate(dir)?;
        Ok(g)
    }

    /// The pixel layout its depth implies.
    pub fn format(&self, path: &Path) -> Result<PixelFormat, ViewError> {
        match self.bits_per_pixel {
            16 => Ok(PixelFormat::Rgb565),
            24 => Ok(PixelFormat::Rgb888),
            32 => Ok(PixelFormat::Xrgb8888),
            bits_per_pixel => Err(ViewError::UnsupportedFormat { path: path.to_path_buf(), bits_per_pixel }),
        }
    }

    fn validate(&self, path: &Path) -> Result<(), ViewError> {
        let format = self.format(path)?;
        let bad = |reason: String| ViewError::Framebuffer { path: path.to_path_buf(), reason };
        if self.width == 0 || self.height == 0 || self.width > MAX_SIDE_PX || self.height > MAX_SIDE_PX {
            return Err(bad(format!("unusable size {}x{}", self.width, self.height)));
        }
        let row = self.width as usize * format.bytes_per_pixel();
        if (self.stride_bytes as usize) < row || self.stride_bytes as usize > row + 64 * 1024 {
            return Err(bad(format!("stride {} B does not fit rows of {row} B", self.stride_bytes)));
        }
        Ok(())
    }

    /// Bytes of the visible area.
    pub fn len_bytes(&self) -> usize {
        self.stride_bytes as usize * self.height as usize
    }
}

/// The sysfs directory of a device node: `/dev/fb1` -> `/sys/class/graphics/fb1`.
pub fn sysfs_dir_for(device: &Path) -> Result<PathBuf, ViewError> {
    match device.file_name().and_then(|n| n.to_str()) {
        Some(name) if name.starts_with("fb") => Ok(Path::new("/sys/class/graphics").join(name)),
        _ => Err(ViewError::Framebuffer {
            path: device.to_path_buf(),
            reason: "not an fbN device: give its geometry explicitly".into(),
        }),
    }
}

/// An open framebuffer with a buffer the size of its visible area.
pub struct Framebuffer {
    file: File,
    path: PathBuf,
    geometry: FbGeometry,
    format: PixelFormat,
    buf: Vec<u8>,
}

impl Framebuffer {
    /// Opens `device` (e.g. `/dev/fb0`) with the geometry from its sysfs directory.
    pub fn open(device: &Path) -> Result<Self, ViewError> {
        Self::open_with_sysfs(device, &sysfs_dir_for(device)?)
    }

    /// Opens `device` with the geometry read from `sysfs_dir`.
    pub fn open_with_sysfs(device: &Path, sysfs_dir: &Path) -> Result<Self, ViewError> {
        Self::open_with_geometry(device, FbGeometry::from_sysfs(sysfs_dir)?)
    }

    /// Opens `device` with a geometry given by config.
    pub fn open_with_geometry(device: &Path, geometry: FbGeometry) -> Result<Self, ViewError> {
        geometry.validate(device)?;
        let format = geometry.format(device)?;
        let file = OpenOptions::new().write(true).open(device).map_err(|e| ViewError::Framebuffer {
            path: device.to_path_buf(),
            reason: match e.kind() {
                std::io::ErrorKind::NotFound => "no such device (is the display's driver loaded?)".into(),
                std::io::ErrorKind::PermissionDenied => "permission denied (add the user to group video)".into(),
                _ => format!("opening: {e}"),
            },
        })?;
        Ok(Self { file, path: device.to_path_buf(), geometry, format, buf: vec![0; geometry.len_bytes()] })
    }

    pub fn geometry(&self) -> FbGeometry {
        self.geometry
    }

    pub fn format(&self) -> PixelFormat {
        self.format
    }

    /// Scales `frame` into the visible area and writes it.
    pub fn write_frame(&mut self, frame: &ArFrame) -> Result<(), ViewError> {
        convert(frame, &self.geometry, self.format, &mut self.buf)?;
        self.file.write_all_at(&self.buf, 0).map_err(|e| ViewError::Framebuffer {
            path: self.path.clone(),
            reason: format!("writing {} B: {e}", self.buf.len()),
        })
    }
}

/// Where the frame lands: its scaled size and top-left corner on the display.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Placement {
    pub x: u32,
    pub y: u32,
    pub width: u32,
    pub height: u32,
}

/// The largest size with the frame's aspect ratio that fits the display, centred.
pub fn placement(frame_w: u32, frame_h: u32, fb_w: u32, fb_h: u32) -> Placement {
    let (fw, fh, dw, dh) = (u64::from(frame_w.max(1)), u64::from(frame_h.max(1)), u64::from(fb_w), u64::from(fb_h));
    // Width-limited unless that makes it too tall.
    let (w, h) = if dw * fh <= dh * fw { (dw, (dw * fh / fw).max(1)) } else { ((dh * fw / fh).max(1), dh) };
    let (w, h) = (w.min(dw) as u32, h.min(dh) as u32);
    Placement { x: (fb_w - w) / 2, y: (fb_h - h) / 2, width: w, height: h }
}

/// Fills `out` (resized to the visible area) with `frame` scaled, centred and encoded.
pub fn convert(frame: &ArFrame, g: &FbGeometry, format: PixelFormat, out: &mut Vec<u8>) -> Result<(), ViewError> {
    check_frame(frame)?;
    out.clear();
    out.resize(g.len_bytes(), 0);
    let p = placement(frame.width, frame.height, g.width, g.height);
    let bpp = format.bytes_per_pixel();
    // Source column for each destination column, computed once per frame rather than per pixel.
    let columns: Vec<usize> =
        (0..p.width).map(|x| (u64::from(x) * u64::from(frame.width) / u64::from(p.width)) as usize).collect();
    let src_row_bytes = frame.width as usize * 3;
    for y in 0..p.height {
        let sy = (u64::from(y) * u64::from(frame.height) / u64::from(p.height)) as usize;
        let Some(src_row) = frame.rgb.get(sy * src_row_bytes..(sy + 1) * src_row_bytes) else { continue };
        let row_start = (p.y + y) as usize * g.stride_bytes as usize + p.x as usize * bpp;
        let Some(dst_row) = out.get_mut(row_start..row_start + p.width as usize * bpp) else { continue };
        for (dst, &sx) in dst_row.chunks_exact_mut(bpp).zip(&columns) {
            if let Some(&[r, g, b]) = src_row.get(sx * 3..sx * 3 + 3) {
                format.encode([r, g, b], dst);
            }
        }
    }
    Ok(())
}

/// Writes frames from `frames` to `fb` until shutdown (blocking writes off the async threads).
pub fn follow(fb: Framebuffer, frames: SnapshotReceiver, shutdown: Shutdown) -> JoinHandle<()> {
    super::hub::follow_blocking("framebuffer", fb, |fb, s| fb.write_frame(&s.frame), frames, shutdown)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn placement_keeps_the_aspect_ratio_and_centres() {
        assert_eq!(placement(640, 480, 320, 240), Placement { x: 0, y: 0, width: 320, height: 240 });
        assert_eq!(placement(640, 480, 480, 320), Placement { x: 27, y: 0, width: 426, height: 320 });
        assert_eq!(placement(640, 480, 320, 480), Placement { x: 0, y: 120, width: 320, height: 240 });
        assert_eq!(placement(4, 2, 4, 2), Placement { x: 0, y: 0, width: 4, height: 2 });
    }

    #[test]
    fn pixel_layouts() {
        let mut out = [0u8; 4];
        PixelFormat::Rgb565.encode([255, 0, 0], &mut out);
        assert_eq!(out[..2], [0x00, 0xf8]);
        PixelFormat::Rgb565.encode([0, 255, 0], &mut out);
        assert_eq!(out[..2], [0xe0, 0x07]);
        PixelFormat::Rgb888.encode([1, 2, 3], &mut out);
        assert_eq!(out[..3], [3, 2, 1]);
        PixelFormat::Xrgb8888.encode([1, 2, 3], &mut out);
        assert_eq!(out, [3, 2, 1, 0]);
    }
}
