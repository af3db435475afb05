//! Camera pixel formats to RGBA8: what webcams deliver (MJPEG, YUYV 4:2:2, NV12, grey, packed
//! RGB/BGR). Pure functions, so they are tested without a device.

/// A camera frame's pixel layout.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PixelFormat {
    /// Motion JPEG: each frame a JPEG file.
    Mjpeg,
    /// YUYV 4:2:2: Y0 U Y1 V per two pixels.
    Yuyv,
    /// NV12: a Y plane, then interleaved U V at half resolution in both directions.
    Nv12,
    /// 8-bit grey.
    Gray,
    /// Packed R G B.
    Rgb,
    /// Packed B G R.
    Bgr,
}

use crate::VideoError;

/// Converts one frame to RGBA8 (`width * height * 4` bytes); errors name the format and the
/// sizes when the data does not fit.
pub fn to_rgba(
    format: PixelFormat,
    width: u32,
    height: u32,
    data: &[u8],
) -> Result<Vec<u8>, VideoError> {
    let n = width as usize * height as usize;
    let what = || format!("{format:?} frame {width}x{height}");
    let bad = |message: String| VideoError::BadFrame {
        what: what(),
        message,
    };
    let need = |bytes: usize| -> Result<(), VideoError> {
        if data.len() < bytes || n == 0 {
            Err(bad(format!("needs {bytes} bytes, got {}", data.len())))
        } else {
            Ok(())
        }
    };
    let mut out = Vec::with_capacity(n * 4);
    match format {
        PixelFormat::Mjpeg => {
            let img = image::load_from_memory_with_format(data, image::ImageFormat::Jpeg)
                .map_err(|source| VideoError::Decode {
                    what: what(),
                    source,
                })?
                .to_rgba8();
            if img.dimensions() != (width, height) {
                return Err(bad(format!(
                    "decodes to {}x{}, the stream says {width}x{height}",
                    img.width(),
                    img.height()
                )));
            }
            return Ok(img.into_raw());
        }
        PixelFormat::Yuyv => {
            if !width.is_multiple_of(2) {
                return Err(bad("the width is odd".into()));
            }
            need(n * 2)?;
            for q in data[..n * 2].chunks_exact(4) {
                let (u, v) = (q[1], q[3]);
                out.extend_from_slice(&yuv_to_rgba(q[0], u, v));
                out.extend_from_slice(&yuv_to_rgba(q[2], u, v));
            }
        }
        PixelFormat::Nv12 => {
            if !width.is_multiple_of(2) || !height.is_multiple_of(2) {
                return Err(bad("the size is odd".into()));
            }
            need(n + n / 2)?;
            let (luma, chroma) = data.split_at(n);
            let w = width as usize;
            for y in 0..height as usize {
                for x in 0..w {
                    let c = (y / 2) * w + (x / 2) * 2;
                    out.extend_from_slice(&yuv_to_rgba(luma[y * w + x], chroma[c], chroma[c + 1]));
                }
            }
        }
        PixelFormat::Gray => {
            need(n)?;
            for &g in &data[..n] {
                out.extend_from_slice(&[g, g, g, 255]);
            }
        }
        PixelFormat::Rgb | PixelFormat::Bgr => {
            need(n * 3)?;
            for p in data[..n * 3].chunks_exact(3) {
                if format == PixelFormat::Rgb {
                    out.extend_from_slice(&[p[0], p[1], p[2], 255]);
                } else {
                    out.extend_from_slice(&[p[2], p[1], p[0], 255]);
                }
            }
        }
    }
    Ok(out)
}

/// BT.601 limited range (what UVC webcams send) to RGBA8, integer arithmetic.
fn yuv_to_rgba(y: u8, u: u8, v: u8) -> [u8; 4] {
    let c = i32::from(y) - 16;
    let d = i32::from(u) - 128;
    let e = i32::from(v) - 128;
    let clamp = |x: i32| ((x + 128) >> 8).clamp(0, 255) as u8;
    [
        clamp(298 * c + 409 * e),
        clamp(298 * c - 100 * d - 208 * e),
        clamp(298 * c + 516 * d),
        255,
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn yuv_black_white_and_primaries() {
        assert_eq!(yuv_to_rgba(16, 128, 128), [0, 0, 0, 255]);
        assert_eq!(yuv_to_rgba(235, 128, 128), [255, 255, 255, 255]);
        // BT.601 red: Y 81, U 90, V 240.
        let red = yuv_to_rgba(81, 90, 240);
        assert!(red[0] > 250 && red[1] < 5 && red[2] < 5, "{red:?}");
    }

    #[test]
    fn every_format_converts_and_short_data_is_refused() {
        let yuyv = [235u8, 128, 16, 128];
        assert_eq!(
            to_rgba(PixelFormat::Yuyv, 2, 1, &yuyv).expect("yuyv"),
            vec![255, 255, 255, 255, 0, 0, 0, 255]
        );
        let nv12 = [235u8, 16, 235, 16, 128, 128];
        let out = to_rgba(PixelFormat::Nv12, 2, 2, &nv12).expect("nv12");
        assert_eq!(&out[..8], &[255, 255, 255, 255, 0, 0, 0, 255]);
        assert_eq!(
            to_rgba(PixelFormat::Bgr, 1, 1, &[1, 2, 3]).expect("bgr"),
            vec![3, 2, 1, 255]
        );
        assert_eq!(
            to_rgba(PixelFormat::Gray, 2, 1, &[7, 9]).expect("gray"),
            vec![7, 7, 7, 255, 9, 9, 9, 255]
        );
        let short = to_rgba(PixelFormat::Rgb, 2, 2, &[0; 5]).expect_err("short");
        assert!(
            short.to_string().contains("needs 12 bytes, got 5"),
            "{short}"
        );
        assert!(to_rgba(PixelFormat::Yuyv, 3, 1, &[0; 6]).is_err());
        assert!(to_rgba(PixelFormat::Mjpeg, 2, 2, b"not a jpeg").is_err());
    }

    #[test]
    fn mjpeg_frames_decode_at_their_size() {
        let img = image::RgbImage::from_pixel(4, 2, image::Rgb([200, 40, 40]));
        let mut jpeg = Vec::new();
        image::DynamicImage::ImageRgb8(img)
            .write_to(
                &mut std::io::Cursor::new(&mut jpeg),
                image::ImageFormat::Jpeg,
            )
            .expect("encode");
        let rgba = to_rgba(PixelFormat::Mjpeg, 4, 2, &jpeg).expect("decode");
        assert_eq!(rgba.len(), 32);
        assert!(rgba[0] > 150 && rgba[1] < 90, "{:?}", &rgba[..4]);
        assert!(to_rgba(PixelFormat::Mjpeg, 8, 8, &jpeg).is_err());
    }
}
