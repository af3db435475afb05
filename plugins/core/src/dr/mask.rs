//! The robot's mask: the twin's render thresholded with the paper's RGBα ranges, dilated and
//! feathered; and a conservative robot region from each link's bounding sphere.

use nalgebra::{Isometry3, Point3};

use super::RgbaView;
use crate::error::{Error, Result};
use crate::robot::{RobotModel, Shape};
use crate::vision::camera::PinholeCamera;
use crate::vision::distortion::{DistortionMap, NO_TEXEL};

/// Whether an RGBA pixel lies inside every channel's range.
pub fn in_ranges(px: &[u8], ranges: &[[u8; 2]; 4]) -> bool {
    px.iter()
        .zip(ranges)
        .all(|(&v, r)| (r[0]..=r[1]).contains(&v))
}

/// The raw texel a full-resolution pixel reads: nearest, by integer arithmetic (the GPU pass
/// computes the same).
pub fn raw_index(x: u32, full: u32, raw: u32) -> u32 {
    (((2 * u64::from(x) + 1) * u64::from(raw)) / (2 * u64::from(full))) as u32
}

/// Thresholds the twin's render `raw` into a `width × height` mask (0/1), dilated by a square
/// window of radius `radius` (pixels outside the image repeat the edge). Through a lens
/// (`lens`, whose `pinhole` is `raw`'s size and whose image is `width × height`), each pixel
/// reads the texel its ray lands on ([`DistortionMap::texels`]; none: not robot); without
/// one, its nearest texel at `raw`'s scale ([`raw_index`]). The GPU pass computes the same.
/// Errors: a lens whose sizes are not these.
pub fn threshold_mask(
    raw: &RgbaView,
    width: u32,
    height: u32,
    ranges: &[[u8; 2]; 4],
    radius: u32,
    lens: Option<&DistortionMap>,
) -> Result<Vec<u8>> {
    let (w, h) = (width as usize, height as usize);
    if let Some(map) = lens {
        if (map.image.width, map.image.height) != (width, height)
            || (map.pinhole.width, map.pinhole.height) != (raw.width, raw.height)
        {
            return Err(Error::BadImage {
                what: "mask twin render".into(),
                message: format!(
                    "is {}x{} for a {width}x{height} mask, but the lens maps a {}x{} image onto a {}x{} render",
                    raw.width,
                    raw.height,
                    map.image.width,
                    map.image.height,
                    map.pinhole.width,
                    map.pinhole.height
                ),
            });
        }
        let mask: Vec<u8> = map
            .texels
            .iter()
            .map(|t| {
                let at = (t[1] as usize * raw.width as usize + t[0] as usize) * 4;
                u8::from(t[0] != NO_TEXEL && in_ranges(&raw.data[at..at + 4], ranges))
            })
            .collect();
        return Ok(dilate(&mask, width, height, radius));
    }
    let xs: Vec<usize> = (0..width)
        .map(|x| raw_index(x, width, raw.width) as usize)
        .collect();
    let mut mask = vec![0u8; w * h];
    for y in 0..height {
        let ry = raw_index(y, height, raw.height) as usize;
        let row = &raw.data[ry * raw.width as usize * 4..][..raw.width as usize * 4];
        let out = &mut mask[y as usize * w..][..w];
        for (o, &rx) in out.iter_mut().zip(&xs) {
            *o = u8::from(in_ranges(&row[rx * 4..rx * 4 + 4], ranges));
        }
    }
    Ok(dilate(&mask, width, height, radius))
}

/// Square (Chebyshev) dilation of a 0/1 mask, separable; the edge repeats.
pub fn dilate(mask: &[u8], width: u32, height: u32, radius: u32) -> Vec<u8> {
    if radius == 0 {
        return mask.to_vec();
    }
    let (w, h, r) = (width as usize, height as usize, radius as usize);
    let mut rows = vec![0u8; w * h];
    for y in 0..h {
        let src = &mask[y * w..][..w];
        let dst = &mut rows[y * w..][..w];
        window_max(src, dst, r);
    }
    let mut out = vec![0u8; w * h];
    let mut col = vec![0u8; h];
    let mut col_out = vec![0u8; h];
    for x in 0..w {
        for y in 0..h {
            col[y] = rows[y * w + x];
        }
        window_max(&col, &mut col_out, r);
        for y in 0..h {
            out[y * w + x] = col_out[y];
        }
    }
    out
}

/// Square (Chebyshev) erosion of a 0/1 mask: the complement's dilation, complemented (the
/// edge repeats).
pub fn erode(mask: &[u8], width: u32, height: u32, radius: u32) -> Vec<u8> {
    let inverse: Vec<u8> = mask.iter().map(|&v| u8::from(v == 0)).collect();
    dilate(&inverse, width, height, radius)
        .iter()
        .map(|&v| u8::from(v == 0))
        .collect()
}

/// The robot's silhouette in `frame` from an empty-room photograph `background` of the same
/// camera (classic background subtraction): a pixel is foreground where some channel differs
/// by more than `threshold` levels; a closing (dilate, erode) of `close_px` fills the holes
/// where the robot's colour happens to match the room, then an opening (erode, dilate) of 1 px
/// removes the sensor noise's specks (and parts thinner than 3 px). Returns 0/1 per pixel.
/// Errors: sizes that differ.
pub fn background_difference(
    frame: &RgbaView,
    background: &RgbaView,
    threshold: u8,
    close_px: u32,
) -> Result<Vec<u8>> {
    super::same_size(frame, background, "empty-room background")?;
    let (w, h) = (frame.width, frame.height);
    let raw = differs(frame.data, background.data, threshold);
    let closed = erode(&dilate(&raw, w, h, close_px), w, h, close_px);
    Ok(dilate(&erode(&closed, w, h, 1), w, h, 1))
}

/// 1 where some RGB channel of the RGBA8 images `a` and `b` differs by more than `levels`,
/// per pixel.
pub fn differs(a: &[u8], b: &[u8], levels: u8) -> Vec<u8> {
    a.chunks_exact(4)
        .zip(b.chunks_exact(4))
        .map(|(p, q)| u8::from((0..3).any(|c| p[c].abs_diff(q[c]) > levels)))
        .collect()
}

/// `dst[i] = max(src[i - r ..= i + r])` (clamped), by a running count of ones.
fn window_max(src: &[u8], dst: &mut [u8], r: usize) {
    let n = src.len();
    let mut count = 0usize;
    for &v in &src[..r.min(n - 1) + 1] {
        count += usize::from(v);
    }
    for i in 0..n {
        dst[i] = u8::from(count > 0);
        let add = i + r + 1;
        if add < n {
            count += usize::from(src[add]);
        }
        if i >= r {
            count -= usize::from(src[i - r]);
        }
    }
}

/// Feathered alpha in `[0, 1]`: the mean of `mask` over a square window of radius `feather`
/// (edge repeats). With `feather = 0` it is the mask itself.
pub fn feather_alpha(mask: &[u8], width: u32, height: u32, feather: u32) -> Vec<f32> {
    if feather == 0 {
        return mask.iter().map(|&m| f32::from(m)).collect();
    }
    let (w, h, f) = (width as usize, height as usize, feather as i64);
    let clamp = |v: i64, n: usize| v.clamp(0, n as i64 - 1) as usize;
    // Horizontal window sums, then vertical: integer counts, exact.
    let mut rows = vec![0u32; w * h];
    for y in 0..h {
        for x in 0..w {
            rows[y * w + x] = (-f..=f)
                .map(|d| u32::from(mask[y * w + clamp(x as i64 + d, w)]))
                .sum();
        }
    }
    let area = ((2 * f + 1) * (2 * f + 1)) as f32;
    let mut out = vec![0f32; w * h];
    for y in 0..h {
        for x in 0..w {
            let sum: u32 = (-f..=f).map(|d| rows[clamp(y as i64 + d, h) * w + x]).sum();
            out[y * w + x] = sum as f32 / area;
        }
    }
    out
}

/// A 0/1 mask from an 8-bit image of `bytes_per_pixel` channels (1: a grey `R8` image, 4:
/// RGBA8) that encodes one as black and white (a read-back mask, a silhouette render): 1
/// where the first channel is above half scale (`> 127`).
pub fn binarise(data: &[u8], bytes_per_pixel: usize) -> Vec<u8> {
    data.chunks_exact(bytes_per_pixel.max(1))
        .map(|px| u8::from(px[0] > 127))
        .collect()
}

/// A grey image (one byte per pixel) as the RGBA8 image a flat-shaded render of it is:
/// `(v, v, v, 255)` per pixel.
pub fn grey_to_rgba(grey: &[u8]) -> Vec<u8> {
    grey.iter().flat_map(|&v| [v, v, v, 255]).collect()
}

/// A bounding sphere of a link's visual geometry, in the link frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinkSphere {
    /// Index of the link in the model.
    pub link: usize,
    /// Centre in the link frame.
    pub centre: Point3<f64>,
    /// Radius (m).
    pub radius: f64,
}

/// Bounding spheres of every visual of the robot. Meshes use the bounds of the loaded file;
/// a mesh that cannot be loaded gets a 0.2 m sphere at its origin (with a note in the result).
pub fn link_spheres(model: &RobotModel) -> (Vec<LinkSphere>, Vec<String>) {
    let mut out = Vec::new();
    let mut notes = Vec::new();
    for (li, link) in model.links.iter().enumerate() {
        for g in &link.visuals {
            let o = g.origin.translation.vector;
            let (centre, radius) = match &g.shape {
                Shape::Box { size } => (o, 0.5 * size.norm()),
                Shape::Cylinder { radius, length } => (o, radius.hypot(0.5 * length)),
                Shape::Capsule { radius, length } => (o, radius + 0.5 * length),
                Shape::Sphere { radius } => (o, *radius),
                Shape::Mesh { path, scale, .. } => {
                    match crate::robot::mesh::load_mesh(path, scale)
                        .ok()
                        .and_then(|m| m.bounds())
                    {
                        Some((lo, hi)) => {
                            let lo = nalgebra::Vector3::new(lo[0], lo[1], lo[2]).cast::<f64>();
                            let hi = nalgebra::Vector3::new(hi[0], hi[1], hi[2]).cast::<f64>();
                            let centre = g.origin * Point3::from(0.5 * (lo + hi));
                            (centre.coords, 0.5 * (hi - lo).norm())
                        }
                        None => {
                            notes.push(format!(
                                "link '{}': mesh {} has no bounds; using a 0.2 m sphere",
                                link.name,
                                path.display()
                            ));
                            (o, 0.2)
                        }
                    }
                }
            };
            out.push(LinkSphere {
                link: li,
                centre: Point3::from(centre),
                radius,
            });
        }
    }
    (out, notes)
}

/// A conservative robot region for photometric fitting and background refresh: every link's
/// bounding sphere projected into the camera, grown by `margin_px`. Spheres behind the camera
/// are skipped. Returns a 0/1 map of `width × height` of the camera.
pub fn sphere_mask(
    camera: &PinholeCamera,
    link_poses: &[Isometry3<f64>],
    spheres: &[LinkSphere],
    margin_px: f64,
) -> Vec<u8> {
    let k = &camera.intrinsics;
    let (w, h) = (k.width as usize, k.height as usize);
    let mut mask = vec![0u8; w * h];
    for s in spheres {
        let Some(pose) = link_poses.get(s.link) else {
            continue;
        };
        let Some((u, v, z)) = camera.project(&(pose * s.centre)) else {
            continue;
        };
        if z <= s.radius {
            // The camera is inside the sphere: everything may be robot.
            mask.fill(1);
            return mask;
        }
        // The silhouette of a sphere is within the circle of its tangent cone's radius.
        let r = k.fx.max(k.fy) * s.radius / (z * z - s.radius * s.radius).sqrt() + margin_px;
        let (y0, y1) = ((v - r).floor().max(0.0), (v + r).ceil().min(h as f64 - 1.0));
        let mut y = y0;
        while y <= y1 {
            let dy = y - v;
            let half = (r * r - dy * dy).max(0.0).sqrt();
            let (x0, x1) = (
                (u - half).floor().max(0.0),
                (u + half).ceil().min(w as f64 - 1.0),
            );
            if x0 <= x1 {
                let row = y as usize * w;
                mask[row + x0 as usize..=row + x1 as usize].fill(1);
            }
            y += 1.0;
        }
    }
    mask
}
