//! The framebuffer output (view/src/framebuffer.rs) against a regular file standing in for
//! `/dev/fbN` and a fake sysfs directory: geometry read from sysfs, the frame scaled and centred,
//! pixels checked in each layout (RGB565, RGB888, XRGB8888) at known places, clear errors for
//! a missing device and an unsupported depth.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use starc_pipeline::ar::ArFrame;
use starc_view::framebuffer::{FbGeometry, Framebuffer, PixelFormat};
use starc_view::{ViewError, ViewHub, ViewStatus};
use std::path::Path;

/// Four quadrants: red, green / blue, white; 8x6.
fn quadrants() -> ArFrame {
    let (w, h) = (8u32, 6u32);
    let mut rgb = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let c = match (x < w / 2, y < h / 2) {
                (true, true) => [255, 0, 0],
                (false, true) => [0, 255, 0],
                (true, false) => [0, 0, 255],
                (false, false) => [255, 255, 255],
            };
            rgb.extend_from_slice(&c);
        }
    }
    ArFrame { width: w, height: h, rgb }
}

fn fake_sysfs(dir: &Path, w: u32, h: u32, bpp: u32, stride: u32) {
    std::fs::create_dir_all(dir).unwrap();
    std::fs::write(dir.join("virtual_size"), format!("{w},{h}\n")).unwrap();
    std::fs::write(dir.join("bits_per_pixel"), format!("{bpp}\n")).unwrap();
    std::fs::write(dir.join("stride"), format!("{stride}\n")).unwrap();
}

/// The pixel at (x, y) of a written framebuffer file, in its layout's bytes.
fn px(buf: &[u8], stride: usize, bpp: usize, x: usize, y: usize) -> Vec<u8> {
    buf[y * stride + x * bpp..y * stride + (x + 1) * bpp].to_vec()
}

#[test]
fn each_layout_gets_the_right_pixels_scaled_and_centred() {
    let dir = tempfile::tempdir().unwrap();
    // 16x20 display (portrait), padded rows: the 8x6 frame scales 2x to 16x12, centred with
    // 4 black rows above and below.
    for (bpp, red, green, blue, white) in [
        (16u32, vec![0x00, 0xf8], vec![0xe0, 0x07], vec![0x1f, 0x00], vec![0xff, 0xff]),
        (24, vec![0, 0, 255], vec![0, 255, 0], vec![255, 0, 0], vec![255, 255, 255]),
        (32, vec![0, 0, 255, 0], vec![0, 255, 0, 0], vec![255, 0, 0, 0], vec![255, 255, 255, 0]),
    ] {
        let bytes = (bpp / 8) as usize;
        let stride = 16 * bytes + 8;
        let sysfs = dir.path().join(format!("fb{bpp}"));
        fake_sysfs(&sysfs, 16, 20, bpp, stride as u32);
        let device = dir.path().join(format!("dev_fb{bpp}"));
        // The device holds junk beforehand: the borders must be written black.
        std::fs::write(&device, vec![0xaau8; stride * 20]).unwrap();
        let mut fb = Framebuffer::open_with_sysfs(&device, &sysfs).unwrap();
        assert_eq!(
            fb.geometry(),
            FbGeometry { width: 16, height: 20, bits_per_pixel: bpp, stride_bytes: stride as u32 }
        );
        fb.write_frame(&quadrants()).unwrap();
        let buf = std::fs::read(&device).unwrap();
        assert_eq!(buf.len(), stride * 20, "{bpp} bpp");
        let black = vec![0u8; bytes];
        let p = |x, y| px(&buf, stride, bytes, x, y);
        assert_eq!(p(0, 0), black, "{bpp} bpp: border above");
        assert_eq!(p(15, 3), black, "{bpp} bpp: border above");
        assert_eq!(p(0, 4), red, "{bpp} bpp");
        assert_eq!(p(7, 9), red, "{bpp} bpp");
        assert_eq!(p(8, 4), green, "{bpp} bpp");
        assert_eq!(p(15, 9), green, "{bpp} bpp");
        assert_eq!(p(0, 10), blue, "{bpp} bpp");
        assert_eq!(p(7, 15), blue, "{bpp} bpp");
        assert_eq!(p(8, 10), white, "{bpp} bpp");
        assert_eq!(p(15, 15), white, "{bpp} bpp");
        assert_eq!(p(3, 16), black, "{bpp} bpp: border below");
        // Row padding is written (as zeros) too, never left as it was.
        assert!(buf[16 * bytes..stride].iter().all(|&b| b == 0), "{bpp} bpp: padding");
    }
}

#[test]
fn downscaling_samples_the_nearest_pixel() {
    let dir = tempfile::tempdir().unwrap();
    let device = dir.path().join("fb");
    std::fs::write(&device, b"").unwrap();
    // 4x3 display at 32 bpp: the 8x6 frame halves; each quadrant becomes 2x1.5 -> rows 0, 1
    // from the top half, row 2 from the bottom.
    let g = FbGeometry { width: 4, height: 3, bits_per_pixel: 32, stride_bytes: 16 };
    let mut fb = Framebuffer::open_with_geometry(&device, g).unwrap();
    assert_eq!(fb.format(), PixelFormat::Xrgb8888);
    fb.write_frame(&quadrants()).unwrap();
    let buf = std::fs::read(&device).unwrap();
    let p = |x, y| px(&buf, 16, 4, x, y);
    assert_eq!(p(0, 0), [0, 0, 255, 0]);
    assert_eq!(p(1, 1), [0, 0, 255, 0]);
    assert_eq!(p(2, 0), [0, 255, 0, 0]);
    assert_eq!(p(0, 2), [255, 0, 0, 0]);
    assert_eq!(p(3, 2), [255, 255, 255, 0]);
}

#[test]
fn clear_errors_for_missing_devices_and_unsupported_formats() {
    let dir = tempfile::tempdir().unwrap();
    let sysfs = dir.path().join("fb0");
    fake_sysfs(&sysfs, 16, 20, 32, 64);
    let missing = dir.path().join("no_such_fb");
    let e = Framebuffer::open_with_sysfs(&missing, &sysfs).err().unwrap();
    assert!(matches!(e, ViewError::Framebuffer { .. }) && e.to_string().contains("no such device"), "{e}");

    let device = dir.path().join("dev");
    std::fs::write(&device, b"").unwrap();
    fake_sysfs(&sysfs, 16, 20, 8, 16);
    let e = Framebuffer::open_with_sysfs(&device, &sysfs).err().unwrap();
    assert!(matches!(e, ViewError::UnsupportedFormat { bits_per_pixel: 8, .. }), "{e}");

    fake_sysfs(&sysfs, 16, 20, 32, 32); // stride shorter than a row
    assert!(Framebuffer::open_with_sysfs(&device, &sysfs).is_err());
    std::fs::write(sysfs.join("virtual_size"), "garbage").unwrap();
    assert!(Framebuffer::open_with_sysfs(&device, &sysfs).is_err());
    let e = Framebuffer::open_with_sysfs(&device, &dir.path().join("nope")).err().unwrap();
    assert!(e.to_string().contains("virtual_size"), "{e}");
    assert!(Framebuffer::open(&dir.path().join("not_fb")).is_err());

    // A frame whose buffer disagrees with its size is refused, not indexed.
    let g = FbGeometry { width: 4, height: 3, bits_per_pixel: 16, stride_bytes: 8 };
    let mut fb = Framebuffer::open_with_geometry(&device, g).unwrap();
    let bad = ArFrame { width: 8, height: 6, rgb: vec![0; 10] };
    assert!(matches!(fb.write_frame(&bad), Err(ViewError::BadFrame { .. })));
    assert!(ViewHub::new().publish(&bad, ViewStatus::default()).is_err());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_follower_writes_published_frames() {
    let dir = tempfile::tempdir().unwrap();
    let device = dir.path().join("fb");
    std::fs::write(&device, b"").unwrap();
    let g = FbGeometry { width: 8, height: 6, bits_per_pixel: 24, stride_bytes: 24 };
    let fb = Framebuffer::open_with_geometry(&device, g).unwrap();
    let hub = ViewHub::new();
    let (stop, shutdown) = tokio::sync::watch::channel(false);
    let task = starc_view::framebuffer::follow(fb, hub.subscribe(), shutdown);
    hub.publish(&quadrants(), ViewStatus::default()).unwrap();
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(5);
    while std::fs::metadata(&device).unwrap().len() < 24 * 6 {
        assert!(std::time::Instant::now() < deadline, "nothing written");
        tokio::time::sleep(std::time::Duration::from_millis(10)).await;
    }
    let buf = std::fs::read(&device).unwrap();
    assert_eq!(px(&buf, 24, 3, 0, 0), [0, 0, 255]);
    assert_eq!(px(&buf, 24, 3, 7, 5), [255, 255, 255]);
    stop.send(true).unwrap();
    tokio::time::timeout(std::time::Duration::from_secs(5), task).await.unwrap().unwrap();
}
