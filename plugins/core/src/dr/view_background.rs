//! A background H that follows a moving camera (Alice's headset camera), for which one
//! photograph cannot serve: the room is re-projected into each frame's view from background
//! views captured at other poses, through a geometric proxy of the room.
//!
//! - [`GeometricProxy`]: the room as rectangles (the faces of the scene's desk, wall and floor
//!   boxes). A pixel's ray hits the nearest rectangle at a point `X`; what is not on the proxy
//!   (the bottle, the glass) is drawn where the proxy is behind it, which is right only near the
//!   view it was captured from (parallax).
//! - [`BackgroundViews`]: captured views (an image, the camera, and which of its pixels may be
//!   used: not covered by the robot); a view is kept when its viewing direction is at least
//!   `min_separation` from every kept one, the oldest going when `max_views` are kept.
//! - [`BackgroundViews::render`]: for each pixel of the target camera, `X` is projected into
//!   every kept view that sees it (the view's own ray through that pixel hits the same
//!   rectangle first, and the pixel is usable), sampled bilinearly over the texels that show
//!   it (weights renormalised, so edges between rectangles leave no holes), and the samples
//!   blended with weights `1 / (θ + θ₀)²`, θ the angle at `X` between the target's and the
//!   view's rays (closest views dominate, as in unstructured lumigraph rendering: Buehler et
//!   al., SIGGRAPH 2001), θ₀ = 0.5°. A ray that meets no rectangle looks at infinity (the
//!   sky, a far room): its direction is projected into the views that see nothing of the proxy
//!   there either.
//!   Pixels no view sees keep a fallback image's pixel, marked unseen.
//!
//! Pixel maps are row-major, top row first; images RGBA8; masks 0/1 per pixel.

use nalgebra::{Isometry3, Point3, Vector3};

use crate::dr::RgbaView;
use crate::error::{Error, Result};
use crate::vision::camera::PinholeCamera;

/// A rectangle of the proxy: `centre ± half_u · u ± half_v · v`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProxyRect {
    /// Centre (m, world).
    pub centre: Point3<f64>,
    /// First in-plane unit axis.
    pub u: Vector3<f64>,
    /// Second in-plane unit axis (orthogonal to `u`).
    pub v: Vector3<f64>,
    /// Half extents along `u` and `v` (m).
    pub half: [f64; 2],
}

impl ProxyRect {
    /// The ray's parameter `t > 1e-6` where `origin + t · dir` meets the rectangle.
    pub fn hit(&self, origin: &Point3<f64>, dir: &Vector3<f64>) -> Option<f64> {
        let n = self.u.cross(&self.v);
        let denom = n.dot(dir);
        if denom.abs() < 1e-12 {
            return None;
        }
        let t = n.dot(&(self.centre - origin)) / denom;
        if t <= 1e-6 {
            return None;
        }
        let d = origin + dir * t - self.centre;
        (d.dot(&self.u).abs() <= self.half[0] && d.dot(&self.v).abs() <= self.half[1]).then_some(t)
    }
}

/// The room as rectangles.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct GeometricProxy {
    /// The rectangles.
    pub rects: Vec<ProxyRect>,
}

impl GeometricProxy {
    /// The six faces of each box; `pose` places the centre of the box's base (as scene props
    /// rest), `size` its extents along its own x, y, z (m).
    pub fn from_boxes(boxes: &[(Isometry3<f64>, [f64; 3])]) -> Self {
        let mut rects = Vec::with_capacity(boxes.len() * 6);
        for (pose, size) in boxes {
            let h = [size[0] / 2.0, size[1] / 2.0, size[2] / 2.0];
            let centre = pose * Point3::new(0.0, 0.0, h[2]);
            let axes = [
                pose.rotation * Vector3::x(),
                pose.rotation * Vector3::y(),
                pose.rotation * Vector3::z(),
            ];
            for a in 0..3 {
                let (b, c) = ((a + 1) % 3, (a + 2) % 3);
                for sign in [-1.0, 1.0] {
                    rects.push(ProxyRect {
                        centre: centre + axes[a] * (sign * h[a]),
                        u: axes[b],
                        v: axes[c],
                        half: [h[b], h[c]],
                    });
                }
            }
        }
        Self { rects }
    }

    /// The nearest rectangle the ray meets: its index and the ray's parameter.
    pub fn hit(&self, origin: &Point3<f64>, dir: &Vector3<f64>) -> Option<(usize, f64)> {
        let mut best: Option<(usize, f64)> = None;
        for (i, r) in self.rects.iter().enumerate() {
            if let Some(t) = r.hit(origin, dir)
                && best.is_none_or(|b| t < b.1)
            {
                best = Some((i, t));
            }
        }
        best
    }

    /// For each pixel of `camera`, the index of the rectangle its ray meets first
    /// ([`NO_RECT`] where none), row-major (`width × height`).
    ///
    /// The rows are cast on `threads` threads (0: one per core, [`default_threads`]; 1: the
    /// calling thread alone); the map is the same whatever the count.
    pub fn rect_map(&self, camera: &PinholeCamera, threads: usize) -> Vec<u16> {
        let k = &camera.intrinsics;
        let (w, h) = (k.width as usize, k.height as usize);
        let origin = Point3::from(camera.world_from_camera.translation.vector);
        let mut out = vec![NO_RECT; w * h];
        let mut none = vec![(); w * h];
        in_row_bands(threads, (&mut out, &mut none), (w, w), |y, row, _| {
            for (x, r) in row.iter_mut().enumerate() {
                let dir = camera.ray(x as f64, y as f64);
                *r = self.hit(&origin, &dir).map_or(NO_RECT, |(i, _)| i as u16);
            }
        });
        out
    }
}

/// Rows per band handed to a thread by [`in_row_bands`]: small enough that a region of a few
/// dozen rows (the robot's) is shared among the threads, large enough that a band's rows are
/// next to each other in memory.
const BAND_ROWS: usize = 4;

/// A band of rows of two images for [`in_row_bands`]: its first row and its elements of each.
type Band<'a, A, B> = (usize, &'a mut [A], &'a mut [B]);

/// Calls `f(y, row_a, row_b)` for each row `y` of two images of equal height, of `widths`
/// elements per row (`a`'s, `b`'s), on `threads` threads (scoped; 0: one per core, 1: the
/// calling thread alone; never more than there are bands). Rows go in bands of [`BAND_ROWS`],
/// dealt round-robin, so a region of work in one part of the image is spread over all
/// threads. Each row is written by one call only.
fn in_row_bands<A: Send, B: Send>(
    threads: usize,
    (a, b): (&mut [A], &mut [B]),
    (width_a, width_b): (usize, usize),
    f: impl Fn(usize, &mut [A], &mut [B]) + Sync,
) {
    if width_a == 0 || width_b == 0 {
        return;
    }
    debug_assert!(
        a.len() % width_a == 0 && b.len() % width_b == 0 && a.len() / width_a == b.len() / width_b,
        "two images of one height"
    );
    let band_count = a.len().div_ceil(width_a * BAND_ROWS);
    let threads = if threads == 0 {
        default_threads()
    } else {
        threads
    }
    .clamp(1, band_count.max(1));
    let mut dealt: Vec<Vec<Band<'_, A, B>>> = (0..threads).map(|_| Vec::new()).collect();
    let bands = a
        .chunks_mut(width_a * BAND_ROWS)
        .zip(b.chunks_mut(width_b * BAND_ROWS));
    for (i, (band_a, band_b)) in bands.enumerate() {
        dealt[i % threads].push((i * BAND_ROWS, band_a, band_b));
    }
    let run = |bands: Vec<Band<'_, A, B>>| {
        for (y0, band_a, band_b) in bands {
            let rows = band_a.chunks_mut(width_a).zip(band_b.chunks_mut(width_b));
            for (dy, (row_a, row_b)) in rows.enumerate() {
                f(y0 + dy, row_a, row_b);
            }
        }
    };
    let mut dealt = dealt.into_iter();
    let Some(own) = dealt.next() else {
        return;
    };
    std::thread::scope(|scope| {
        for bands in dealt.filter(|b| !b.is_empty()) {
            scope.spawn(move || run(bands));
        }
        run(own);
    });
}

/// Threads a [`BackgroundViews`] renders on by default: the machine's cores.
pub fn default_threads() -> usize {
    std::thread::available_parallelism().map_or(1, std::num::NonZero::get)
}

/// In a rectangle map: the pixel's ray meets no rectangle.
pub const NO_RECT: u16 = u16::MAX;

/// One captured background view.
#[derive(Debug, Clone)]
struct CapturedView {
    camera: PinholeCamera,
    rgba: Vec<u8>,
    /// 1 where the pixel shows the room (not the robot).
    usable: Vec<u8>,
    /// [`GeometricProxy::rect_map`] of the view.
    rects: Vec<u16>,
    /// The view's optical axis (world).
    axis: Vector3<f64>,
    /// When it was taken (s), for reports.
    at_s: f64,
    /// Never evicted nor replaced (the empty room's photograph).
    pinned: bool,
}

/// Largest standard deviation of luma (0–255, Rec. 601) over a frame's usable pixels for
/// which the frame is blank ([`BackgroundViews::offer`]): above a sensor's own noise (σ of 1–2
/// levels), below any room (tens of levels). A camera facing a plain wall close up can be
/// blank too; its frames are then not kept as views, which costs nothing but the view.
pub const BLANK_LUMA_STD: f64 = 3.0;

/// Whether `frame`'s pixels outside `covered` have a luma standard deviation below
/// [`BLANK_LUMA_STD`] (false when none is outside: such a view adds nothing anyway).
fn is_blank(frame: &RgbaView, covered: &[u8]) -> bool {
    let (mut n, mut sum, mut sum_sq) = (0u64, 0f64, 0f64);
    for (px, &c) in frame.data.chunks_exact(4).zip(covered) {
        if c != 0 {
            continue;
        }
        let y = 0.299 * f64::from(px[0]) + 0.587 * f64::from(px[1]) + 0.114 * f64::from(px[2]);
        n += 1;
        sum += y;
        sum_sq += y * y;
    }
    if n == 0 {
        return false;
    }
    let mean = sum / n as f64;
    let variance = (sum_sq / n as f64 - mean * mean).max(0.0);
    variance.sqrt() < BLANK_LUMA_STD
}

/// Background views of one image size, and the room re-projected into any view.
#[derive(Debug, Clone)]
pub struct BackgroundViews {
    width: u32,
    height: u32,
    proxy: GeometricProxy,
    /// At most this many views are kept (the oldest goes).
    pub max_views: usize,
    /// A view is kept only this far (rad, between optical axes) from every kept one, or when
    /// it shows a larger share of the room than the nearest kept one.
    pub min_separation_rad: f64,
    /// Threads [`BackgroundViews::render`] and a new view's rectangle map run on (0: one per
    /// core, [`default_threads`], as at first; 1: the calling thread alone; at most one per band
    /// of rows). The result is the same whatever the count.
    pub threads: usize,
    views: Vec<CapturedView>,
    offered: u64,
    blank: u64,
}

/// What [`BackgroundViews::render`] made.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderedBackground {
    /// H, RGBA8 (opaque).
    pub rgba: Vec<u8>,
    /// 1 where some view saw the pixel, 0 where it kept the fallback.
    pub seen: Vec<u8>,
}

impl BackgroundViews {
    /// No views yet; images of `width × height`. Errors: an empty size, `max_views` 0, or a
    /// separation that is not finite and ≥ 0.
    pub fn new(
        width: u32,
        height: u32,
        proxy: GeometricProxy,
        max_views: usize,
        min_separation_rad: f64,
    ) -> Result<Self> {
        if width == 0 || height == 0 || max_views == 0 || proxy.rects.len() >= usize::from(NO_RECT)
        {
            return Err(Error::BadSetting {
                what: "background views".into(),
                message: format!(
                    "{width}x{height}, {max_views} views, {} rectangles: need a size, at least one view and fewer than {NO_RECT} rectangles",
                    proxy.rects.len()
                ),
            });
        }
        if !(min_separation_rad.is_finite() && min_separation_rad >= 0.0) {
            return Err(Error::BadSetting {
                what: "background views".into(),
                message: format!("separation {min_separation_rad} rad is not finite and >= 0"),
            });
        }
        Ok(Self {
            width,
            height,
            proxy,
            max_views,
            min_separation_rad,
            threads: 0,
            views: Vec::new(),
            offered: 0,
            blank: 0,
        })
    }

    /// Views kept.
    pub fn len(&self) -> usize {
        self.views.len()
    }

    /// No view yet.
    pub fn is_empty(&self) -> bool {
        self.views.is_empty()
    }

    /// Views offered so far.
    pub fn offered(&self) -> u64 {
        self.offered
    }

    /// Views refused as blank (see [`BackgroundViews::offer`]).
    pub fn blank(&self) -> u64 {
        self.blank
    }

    /// The capture times of the kept views (s).
    pub fn times(&self) -> Vec<f64> {
        self.views.iter().map(|v| v.at_s).collect()
    }

    /// The smallest angle (rad) between `camera`'s optical axis and a kept view's; `None`
    /// without views.
    pub fn nearest_angle(&self, camera: &PinholeCamera) -> Option<f64> {
        let axis = camera.world_from_camera.rotation * Vector3::z();
        self.views
            .iter()
            .map(|v| v.axis.angle(&axis))
            .reduce(f64::min)
    }

    /// Offers a view taken at `at_s` by `camera` (its intrinsics must be of this size):
    /// `frame`, with `covered` (0/1 per pixel) marking what may not be used (the robot and its
    /// margin). Kept when it is far enough from every kept view (see
    /// [`BackgroundViews::min_separation_rad`]); returns whether it was. A blank frame (its
    /// usable pixels' luma varying less than [`BLANK_LUMA_STD`]: a camera that is not streaming
    /// yet, a renderer before its first frame, a lens cap) is refused: blended with the room,
    /// it would darken H wherever its angle is near.
    pub fn offer(
        &mut self,
        camera: &PinholeCamera,
        frame: &RgbaView,
        covered: &[u8],
        at_s: f64,
    ) -> Result<bool> {
        let n = self.width as usize * self.height as usize;
        let k = &camera.intrinsics;
        if (frame.width, frame.height) != (self.width, self.height)
            || (k.width, k.height) != (self.width, self.height)
            || covered.len() != n
        {
            return Err(Error::BadImage {
                what: "background view".into(),
                message: format!(
                    "frame {}x{}, camera {}x{}, {} mask pixels; the views are {}x{}",
                    frame.width,
                    frame.height,
                    k.width,
                    k.height,
                    covered.len(),
                    self.width,
                    self.height
                ),
            });
        }
        let pose = &camera.world_from_camera;
        if !(pose.translation.vector.iter().all(|v| v.is_finite())
            && pose.rotation.coords.iter().all(|v| v.is_finite()))
        {
            return Err(Error::BadSetting {
                what: "background view".into(),
                message: "the camera's pose is not finite".into(),
            });
        }
        self.offered += 1;
        let axis = camera.world_from_camera.rotation * Vector3::z();
        let usable_share = covered.iter().filter(|&&c| c == 0).count() as f64 / n as f64;
        let nearest = self
            .views
            .iter()
            .enumerate()
            .map(|(i, v)| (i, v.axis.angle(&axis)))
            .min_by(|a, b| a.1.total_cmp(&b.1));
        let replace = match nearest {
            None => None,
            Some((_, angle)) if angle >= self.min_separation_rad => None,
            // As near as a kept view: kept instead of it only when it shows more of the room.
            Some((i, _)) => {
                let kept = &self.views[i];
                let kept_share = kept.usable.iter().filter(|&&u| u > 0).count() as f64 / n as f64;
                if usable_share > kept_share + 0.01 {
                    Some(i)
                } else {
                    return Ok(false);
                }
            }
        };
        // Checked only for a frame that would be kept: the scan costs a pass over the image.
        if is_blank(frame, covered) {
            self.blank += 1;
            return Ok(false);
        }
        let view = CapturedView {
            camera: *camera,
            rgba: frame.data.to_vec(),
            usable: covered.iter().map(|&c| u8::from(c == 0)).collect(),
            rects: self.proxy.rect_map(camera, self.threads),
            axis,
            at_s,
            pinned: false,
        };
        match replace {
            Some(i) if !self.views[i].pinned => self.views[i] = view,
            Some(_) => return Ok(false),
            None => {
                if self.views.len() >= self.max_views && !self.evict_oldest() {
                    return Ok(false);
                }
                self.views.push(view);
            }
        }
        Ok(true)
    }

    /// Removes the unpinned view taken first; false when every view is pinned.
    fn evict_oldest(&mut self) -> bool {
        let oldest = self
            .views
            .iter()
            .enumerate()
            .filter(|(_, v)| !v.pinned)
            .min_by(|a, b| a.1.at_s.total_cmp(&b.1.at_s))
            .map(|(i, _)| i);
        match oldest {
            Some(i) => {
                self.views.remove(i);
                true
            }
            None => false,
        }
    }

    /// Sets the photograph of the room with nothing in the way (the empty room, every pixel
    /// usable), taken at `at_s` by `camera`: it replaces the previous photograph and is never
    /// evicted nor replaced by a frame's view. Errors as [`BackgroundViews::offer`]'s.
    pub fn set_photograph(
        &mut self,
        camera: &PinholeCamera,
        frame: &RgbaView,
        at_s: f64,
    ) -> Result<()> {
        let n = self.width as usize * self.height as usize;
        let k = &camera.intrinsics;
        let pose = &camera.world_from_camera;
        if (frame.width, frame.height) != (self.width, self.height)
            || (k.width, k.height) != (self.width, self.height)
            || !pose.translation.vector.iter().all(|v| v.is_finite())
            || !pose.rotation.coords.iter().all(|v| v.is_finite())
        {
            return Err(Error::BadImage {
                what: "background photograph".into(),
                message: format!(
                    "frame {}x{}, camera {}x{} (its pose finite: {}); the views are {}x{}",
                    frame.width,
                    frame.height,
                    k.width,
                    k.height,
                    pose.translation.vector.iter().all(|v| v.is_finite()),
                    self.width,
                    self.height
                ),
            });
        }
        self.views.retain(|v| !v.pinned);
        if self.views.len() >= self.max_views {
            self.evict_oldest();
        }
        self.views.push(CapturedView {
            camera: *camera,
            rgba: frame.data.to_vec(),
            usable: vec![1; n],
            rects: self.proxy.rect_map(camera, self.threads),
            axis: camera.world_from_camera.rotation * Vector3::z(),
            at_s,
            pinned: true,
        });
        Ok(())
    }

    /// The room as `target` sees it, re-projected from the kept views, at the pixels where
    /// `only` (0/1 per pixel) is 1, or everywhere; pixels not rendered or that no view sees keep
    /// `fallback`'s (an RGBA8 image of this size, drawn over in place), else opaque black.
    pub fn render(
        &self,
        target: &PinholeCamera,
        fallback: Option<Vec<u8>>,
        only: Option<&[u8]>,
    ) -> Result<RenderedBackground> {
        let (w, h) = (self.width as usize, self.height as usize);
        let k = &target.intrinsics;
        if (k.width, k.height) != (self.width, self.height)
            || fallback.as_ref().is_some_and(|f| f.len() != w * h * 4)
            || only.is_some_and(|o| o.len() != w * h)
        {
            return Err(Error::BadImage {
                what: "background target".into(),
                message: format!(
                    "camera {}x{}; the views are {}x{}",
                    k.width, k.height, self.width, self.height
                ),
            });
        }
        let mut rgba = fallback.unwrap_or_else(|| [0, 0, 0, 255].repeat(w * h));
        let mut seen = vec![0u8; w * h];
        let origin = Point3::from(target.world_from_camera.translation.vector);
        in_row_bands(
            self.threads,
            (&mut seen, &mut rgba),
            (w, w * 4),
            |y, seen_row, rgba_row| {
                for x in 0..w {
                    if only.is_some_and(|o| o[y * w + x] == 0) {
                        continue;
                    }
                    if let Some(colour) = self.blend(target, &origin, x, y) {
                        rgba_row[x * 4..x * 4 + 3].copy_from_slice(&colour);
                        rgba_row[x * 4 + 3] = 255;
                        seen_row[x] = 1;
                    }
                }
            },
        );
        Ok(RenderedBackground { rgba, seen })
    }

    /// The room's colour at pixel `(x, y)` of `target` (whose centre is `origin`), blended
    /// from the views that see it; `None` where none does. The weights are
    /// unstructured-lumigraph ones (Buehler et al., SIGGRAPH 2001), 1/(θ + 0.5°)², θ the angle
    /// at the point between the target's ray and the view's, times the view's support there.
    fn blend(
        &self,
        target: &PinholeCamera,
        origin: &Point3<f64>,
        x: usize,
        y: usize,
    ) -> Option<[u8; 3]> {
        let theta0 = 0.5f64.to_radians();
        let dir = target.ray(x as f64, y as f64);
        // Past the proxy: the point is at infinity (the view turns, it does not move).
        let point = self
            .proxy
            .hit(origin, &dir)
            .map(|(r, t)| (r, origin + dir * t));
        let rect = point.map_or(NO_RECT, |(r, _)| r as u16);
        let mut acc = [0.0f64; 3];
        let mut total = 0.0;
        for v in &self.views {
            let (projected, theta) = match point {
                Some((_, p)) => {
                    let eye = Point3::from(v.camera.world_from_camera.translation.vector);
                    (v.camera.project(&p), dir.angle(&(p - eye)))
                }
                None => (project_direction(&v.camera, &dir), 0.0),
            };
            let Some((u, vv, _)) = projected else {
                continue;
            };
            let Some((sample, support)) = v.sample(u, vv, rect) else {
                continue;
            };
            // A view that sees the point through few of its texels counts for less.
            let weight = support / (theta + theta0).powi(2);
            for c in 0..3 {
                acc[c] += weight * sample[c];
            }
            total += weight;
        }
        (total > 0.0).then(|| acc.map(|a| (a / total).round().clamp(0.0, 255.0) as u8))
    }
}

/// Where `camera` sees the world direction `dir` (a point at infinity): `(u, v, 1)`, or `None`
/// behind it.
fn project_direction(camera: &PinholeCamera, dir: &Vector3<f64>) -> Option<(f64, f64, f64)> {
    let d = camera.world_from_camera.rotation.inverse() * dir;
    if d.z <= 1e-9 {
        return None;
    }
    let k = &camera.intrinsics;
    Some((k.fx * d.x / d.z + k.cx, k.fy * d.y / d.z + k.cy, 1.0))
}

impl CapturedView {
    /// The view's colour at `(u, v)`: bilinear over its four texels, of which only those
    /// inside the image, usable and showing rectangle `rect` (the point is not hidden from this
    /// view by another part of the proxy) count, their weights renormalised (normalised
    /// convolution). A point beside a rectangle's edge, a covered region or the image's rim
    /// thus takes its colour from the texels that do show it, instead of being unseen along a
    /// line of dots. Returns the colour and the support (the qualifying texels' share of the
    /// bilinear weight, 0–1]; `None` when that share is under a thousandth.
    fn sample(&self, u: f64, v: f64, rect: u16) -> Option<([f64; 3], f64)> {
        let k = &self.camera.intrinsics;
        if !self.camera.in_image(u, v) {
            return None;
        }
        let (w, h) = (k.width as usize, k.height as usize);
        let (x0, y0) = (u.floor(), v.floor());
        let (fx, fy) = (u - x0, v - y0);
        let mut out = [0.0; 3];
        let mut total = 0.0;
        for (dx, dy, weight) in [
            (0.0, 0.0, (1.0 - fx) * (1.0 - fy)),
            (1.0, 0.0, fx * (1.0 - fy)),
            (0.0, 1.0, (1.0 - fx) * fy),
            (1.0, 1.0, fx * fy),
        ] {
            let (x, y) = (x0 + dx, y0 + dy);
            if weight <= 0.0 || x < 0.0 || y < 0.0 || x >= w as f64 || y >= h as f64 {
                continue;
            }
            let i = y as usize * w + x as usize;
            if self.usable[i] == 0 || self.rects[i] != rect {
                continue;
            }
            for (c, o) in out.iter_mut().enumerate() {
                *o += weight * f64::from(self.rgba[i * 4 + c]);
            }
            total += weight;
        }
        // Below a thousandth of a texel's weight, the colour would come from a texel a pixel
        // away that the point barely touches: unseen instead.
        (total > 1e-3).then(|| (out.map(|c| c / total), total))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vision::camera::Intrinsics;

    fn camera(eye: [f64; 3], target: [f64; 3]) -> PinholeCamera {
        PinholeCamera::looking_at(
            Intrinsics::from_fov_y(50f64.to_radians(), 64, 48),
            eye,
            target,
        )
        .expect("pose")
    }

    /// A desk (a box) before a wall, and two cameras 2.2° apart that see the desk's top and front
    /// and the wall behind: edges where rectangles meet, in both views.
    fn desk_before_wall() -> (GeometricProxy, PinholeCamera, PinholeCamera) {
        let proxy = GeometricProxy::from_boxes(&[
            (Isometry3::translation(-0.01, 0.0, 0.0), [0.02, 4.0, 3.0]),
            (Isometry3::translation(0.5, 0.0, 0.35), [0.6, 1.6, 0.7]),
        ]);
        let a = camera([1.8, -0.3, 1.2], [0.3, 0.0, 0.6]);
        let b = camera([1.75, -0.22, 1.24], [0.3, 0.05, 0.6]);
        (proxy, a, b)
    }

    /// A wall at x = 0 (a thin box) whose colour is a function of the point: what a view sees
    /// at each pixel, computed exactly.
    fn wall() -> GeometricProxy {
        GeometricProxy::from_boxes(&[(Isometry3::translation(-0.01, 0.0, 0.0), [0.02, 4.0, 3.0])])
    }

    fn paint(p: &Point3<f64>) -> [u8; 3] {
        [
            (128.0 + 100.0 * (p.y * 2.0).sin()) as u8,
            (128.0 + 100.0 * (p.z * 3.0).cos()) as u8,
            90,
        ]
    }

    fn photograph(proxy: &GeometricProxy, cam: &PinholeCamera) -> Vec<u8> {
        let k = &cam.intrinsics;
        let origin = Point3::from(cam.world_from_camera.translation.vector);
        let mut out = Vec::new();
        for y in 0..k.height {
            for x in 0..k.width {
                let dir = cam.ray(f64::from(x), f64::from(y));
                let c = match proxy.hit(&origin, &dir) {
                    Some((_, t)) => paint(&(origin + dir * t)),
                    None => [0, 0, 0],
                };
                out.extend_from_slice(&[c[0], c[1], c[2], 255]);
            }
        }
        out
    }

    /// The room photographed from `a`, kept as the only view, and rendered from `b`: the
    /// views, the rendering and `b`'s own photograph (the truth).
    fn one_view_seen_from(
        proxy: &GeometricProxy,
        a: &PinholeCamera,
        b: &PinholeCamera,
    ) -> (BackgroundViews, RenderedBackground, Vec<u8>) {
        let mut views = BackgroundViews::new(64, 48, proxy.clone(), 4, 0.0).expect("views");
        let photo = photograph(proxy, a);
        let frame = RgbaView::new("a", 64, 48, &photo).expect("view");
        assert!(
            views
                .offer(a, &frame, &vec![0; 64 * 48], 0.0)
                .expect("offer")
        );
        let out = views.render(b, None, None).expect("render");
        (views, out, photograph(proxy, b))
    }

    #[test]
    fn a_box_has_six_faces_and_the_nearest_is_hit() {
        let proxy = GeometricProxy::from_boxes(&[(Isometry3::identity(), [1.0, 2.0, 0.5])]);
        assert_eq!(proxy.rects.len(), 6);
        // From above, straight down: the top face at z = 0.5.
        let (i, t) = proxy
            .hit(&Point3::new(0.1, 0.2, 2.0), &-Vector3::z())
            .expect("hit");
        assert!((t - 1.5).abs() < 1e-12);
        assert!((proxy.rects[i].centre.z - 0.5).abs() < 1e-12);
        assert!(
            proxy
                .hit(&Point3::new(3.0, 0.0, 2.0), &-Vector3::z())
                .is_none()
        );
    }

    #[test]
    fn a_view_reprojects_exactly_through_a_plane_and_misses_stay_unseen() {
        let proxy = wall();
        let a = camera([1.5, -0.3, 1.0], [0.0, 0.0, 1.0]);
        let b = camera([1.4, 0.25, 1.05], [0.0, 0.1, 1.0]);
        let (views, out, truth) = one_view_seen_from(&proxy, &a, &b);
        let mut diffs = Vec::new();
        for i in 0..64 * 48 {
            if out.seen[i] > 0 {
                for c in 0..3 {
                    diffs
                        .push((i32::from(out.rgba[i * 4 + c]) - i32::from(truth[i * 4 + c])).abs());
                }
            }
        }
        let seen = out.seen.iter().filter(|&&s| s > 0).count();
        assert!(seen > 64 * 48 / 2, "most of b's view is in a's: {seen}");
        let mean = diffs.iter().sum::<i32>() as f64 / diffs.len() as f64;
        assert!(mean < 3.0, "bilinear resampling of a smooth wall: {mean}");
        // What a never saw stays unseen and keeps the fallback.
        let fallback = vec![7u8; 64 * 48 * 4];
        let out2 = views
            .render(&b, Some(fallback.clone()), None)
            .expect("render");
        for i in 0..64 * 48 {
            if out2.seen[i] == 0 {
                assert_eq!(out2.rgba[i * 4], 7);
            }
        }
        assert!(out2.seen.contains(&0), "b sees past a's edge");
        // Only where asked.
        let mut only = vec![0u8; 64 * 48];
        only[24 * 64 + 32] = 1;
        let out3 = views
            .render(&b, Some(fallback.clone()), Some(&only))
            .expect("render");
        assert_eq!(out3.seen.iter().filter(|&&s| s > 0).count(), 1);
        assert_eq!(out3.rgba[(24 * 64 + 32) * 4], out.rgba[(24 * 64 + 32) * 4]);
    }

    #[test]
    fn where_two_rectangles_meet_the_seam_is_filled_from_the_texels_that_show_it() {
        // A desk (a box) before the wall: its top and front faces meet at an edge that both
        // cameras see, and the wall meets the desk's top behind it.
        let (proxy, a, b) = desk_before_wall();
        let (_, out, truth) = one_view_seen_from(&proxy, &a, &b);
        // Every pixel of b whose point a sees, a texel from its own rim, on the same rectangle,
        // is seen: none left along the edges where rectangles meet.
        let rects_a = proxy.rect_map(&a, 1);
        let origin = Point3::from(b.world_from_camera.translation.vector);
        let (mut checked, mut holes, mut seam) = (0, Vec::new(), 0);
        for y in 0..48u32 {
            for x in 0..64u32 {
                let Some((r, t)) = proxy.hit(&origin, &b.ray(f64::from(x), f64::from(y))) else {
                    continue;
                };
                let p = origin + b.ray(f64::from(x), f64::from(y)) * t;
                let Some((u, v, _)) = a.project(&p) else {
                    continue;
                };
                if !(1.0..62.0).contains(&u) || !(1.0..46.0).contains(&v) {
                    continue;
                }
                let near = (v.round() as usize) * 64 + u.round() as usize;
                if rects_a[near] != r as u16 {
                    continue;
                }
                checked += 1;
                let (x0, y0) = (u.floor() as usize, v.floor() as usize);
                let footprint = [(0, 0), (1, 0), (0, 1), (1, 1)]
                    .map(|(dx, dy)| rects_a[(y0 + dy) * 64 + x0 + dx]);
                if footprint.iter().any(|&q| q != r as u16) {
                    seam += 1;
                }
                let i = (y * 64 + x) as usize;
                if out.seen[i] == 0 {
                    holes.push((x, y));
                }
            }
        }
        assert!(checked > 64 * 48 / 2, "{checked}");
        assert!(seam > 20, "the views straddle edges: {seam} pixels");
        assert!(holes.is_empty(), "unseen on a seam: {holes:?}");
        // And what fills the seam is the room's colour there, as elsewhere.
        let mut diffs = Vec::new();
        for i in 0..64 * 48 {
            if out.seen[i] > 0 && truth[i * 4..i * 4 + 3] != [0, 0, 0] {
                for c in 0..3 {
                    diffs
                        .push((i32::from(out.rgba[i * 4 + c]) - i32::from(truth[i * 4 + c])).abs());
                }
            }
        }
        let mean = diffs.iter().sum::<i32>() as f64 / diffs.len() as f64;
        assert!(mean < 4.0, "{mean}");
    }

    #[test]
    fn a_view_that_sees_a_point_through_few_texels_counts_for_less_in_the_blend() {
        let proxy = wall();
        // a is 1.9 deg from the target, b 3.8 deg: a outweighs b where it sees fully.
        let target = camera([1.5, 0.0, 1.0], [0.0, 0.0, 1.0]);
        let a = camera([1.5, 0.05, 1.0], [0.0, 0.0, 1.0]);
        let b = camera([1.5, -0.1, 1.0], [0.0, 0.0, 1.0]);
        // a's picture is wrong in blue (45 where the room is 90), and only every other texel
        // of every other row is usable, so its support runs from 0 to 1 across the wall.
        let wrong: Vec<u8> = photograph(&proxy, &a)
            .chunks_exact(4)
            .flat_map(|p| [p[0], p[1], p[2] / 2, 255])
            .collect();
        let lattice: Vec<u8> = (0..64 * 48)
            .map(|i| u8::from(!(i % 64 % 2 == 0 && i / 64 % 2 == 0)))
            .collect();
        let right = photograph(&proxy, &b);
        let mut views = BackgroundViews::new(64, 48, proxy.clone(), 4, 0.0).expect("views");
        let fa = RgbaView::new("a", 64, 48, &wrong).expect("a");
        let fb = RgbaView::new("b", 64, 48, &right).expect("b");
        assert!(views.offer(&a, &fa, &lattice, 0.0).expect("a"));
        assert!(views.offer(&b, &fb, &vec![0; 64 * 48], 1.0).expect("b"));
        let out = views.render(&target, None, None).expect("render");
        // a's share of each pixel's colour, read from blue: 90 is b's alone, 45 a's alone.
        let origin = Point3::from(target.world_from_camera.translation.vector);
        let (mut thin, mut full) = (Vec::new(), Vec::new());
        for y in 2..46u32 {
            for x in 2..62u32 {
                let dir = target.ray(f64::from(x), f64::from(y));
                let Some((r, t)) = proxy.hit(&origin, &dir) else {
                    continue;
                };
                let Some((u, v, _)) = a.project(&(origin + dir * t)) else {
                    continue;
                };
                let Some((_, support)) = views.views[0].sample(u, v, r as u16) else {
                    continue;
                };
                let i = (y * 64 + x) as usize;
                let share = (90.0 - f64::from(out.rgba[i * 4 + 2])) / 45.0;
                if support < 0.1 {
                    thin.push(share);
                } else if support > 0.9 {
                    full.push(share);
                }
            }
        }
        let mean = |s: &[f64]| s.iter().sum::<f64>() / s.len() as f64;
        assert!(
            thin.len() > 50 && full.len() > 50,
            "{} {}",
            thin.len(),
            full.len()
        );
        // Unweighted, a would give three quarters of the colour everywhere it sees.
        assert!(mean(&full) > 0.6, "a seen fully wins: {}", mean(&full));
        assert!(
            mean(&thin) < 0.3,
            "a seen through a corner loses: {}",
            mean(&thin)
        );
    }

    #[test]
    fn any_number_of_threads_renders_the_same_image() {
        let (proxy, a, b) = desk_before_wall();
        let mut views = BackgroundViews::new(64, 48, proxy.clone(), 4, 0.0).expect("views");
        views.threads = 1;
        let photo = photograph(&proxy, &a);
        let frame = RgbaView::new("a", 64, 48, &photo).expect("view");
        assert!(
            views
                .offer(&a, &frame, &vec![0; 64 * 48], 0.0)
                .expect("offer")
        );
        // A region of a few rows, as the robot's is: fewer bands than threads in places.
        let only: Vec<u8> = (0..64 * 48)
            .map(|i| u8::from((9..19).contains(&(i / 64))))
            .collect();
        let alone = views.render(&b, None, Some(&only)).expect("render");
        let everywhere = views.render(&b, None, None).expect("render");
        assert!(alone.seen.iter().filter(|&&s| s > 0).count() > 300);
        // More threads than bands of rows: one per band, not one per request.
        for threads in [0, 2, 3, 7, 64, usize::MAX] {
            views.threads = threads;
            assert_eq!(
                views.render(&b, None, Some(&only)).expect("render"),
                alone,
                "{threads}"
            );
            assert_eq!(
                views.render(&b, None, None).expect("render"),
                everywhere,
                "{threads}"
            );
            assert_eq!(
                proxy.rect_map(&b, threads),
                proxy.rect_map(&b, 1),
                "{threads}"
            );
        }
    }

    #[test]
    fn past_the_proxy_the_room_is_at_infinity() {
        // No proxy at all: a turning camera sees the same sky, painted by direction.
        let proxy = GeometricProxy::default();
        let sky = |cam: &PinholeCamera| -> Vec<u8> {
            let k = &cam.intrinsics;
            let mut out = Vec::new();
            for y in 0..k.height {
                for x in 0..k.width {
                    let d = cam.ray(f64::from(x), f64::from(y));
                    out.extend_from_slice(&[
                        (128.0 + 120.0 * d.y) as u8,
                        (128.0 + 120.0 * d.z) as u8,
                        60,
                        255,
                    ]);
                }
            }
            out
        };
        let a = camera([0.0, 0.0, 1.0], [1.0, 0.0, 1.0]);
        let b = camera([0.0, 0.0, 1.0], [1.0, 0.1, 1.05]);
        let mut views = BackgroundViews::new(64, 48, proxy, 2, 0.0).expect("views");
        let photo = sky(&a);
        let f = RgbaView::new("a", 64, 48, &photo).expect("a");
        views.offer(&a, &f, &vec![0; 64 * 48], 0.0).expect("offer");
        let out = views.render(&b, None, None).expect("render");
        let truth = sky(&b);
        let seen: Vec<usize> = (0..64 * 48).filter(|&i| out.seen[i] > 0).collect();
        assert!(seen.len() > 64 * 48 / 2, "{}", seen.len());
        for i in seen {
            let e = (i32::from(out.rgba[i * 4]) - i32::from(truth[i * 4])).abs();
            assert!(e <= 2, "pixel {i}: {e}");
        }
    }

    #[test]
    fn covered_pixels_are_not_used_and_the_nearer_view_wins() {
        let proxy = wall();
        let a = camera([1.5, -0.3, 1.0], [0.0, 0.0, 1.0]);
        let b = camera([1.5, 0.3, 1.0], [0.0, 0.0, 1.0]);
        let target = camera([1.5, 0.25, 1.0], [0.0, 0.0, 1.0]);
        let mut views = BackgroundViews::new(64, 48, proxy.clone(), 4, 0.0).expect("views");
        // a's picture is wrong (a lighting change: the room, red and darker), b's right.
        let wrong: Vec<u8> = photograph(&proxy, &a)
            .chunks_exact(4)
            .flat_map(|p| [p[0].saturating_add(80), p[1] / 2, p[2] / 2, 255])
            .collect();
        let right = photograph(&proxy, &b);
        let fa = RgbaView::new("a", 64, 48, &wrong).expect("a");
        let fb = RgbaView::new("b", 64, 48, &right).expect("b");
        assert!(views.offer(&a, &fa, &vec![0; 64 * 48], 0.0).expect("a"));
        assert!(views.offer(&b, &fb, &vec![0; 64 * 48], 1.0).expect("b"));
        assert_eq!(views.len(), 2);
        let out = views.render(&target, None, None).expect("render");
        let truth = photograph(&proxy, &target);
        let centre = (24 * 64 + 32) * 4;
        let err = (i32::from(out.rgba[centre]) - i32::from(truth[centre])).abs();
        assert!(err < 25, "b (3 deg away) outweighs a (20 deg away): {err}");
        // Covered everywhere: a view that may not be used adds nothing.
        let mut only_covered = BackgroundViews::new(64, 48, proxy, 4, 0.0).expect("views");
        assert!(
            only_covered
                .offer(&a, &fa, &vec![1; 64 * 48], 0.0)
                .expect("offer"),
            "kept: the first view, even with nothing usable"
        );
        assert_eq!(only_covered.blank(), 0, "covered is not blank");
        let out = only_covered.render(&target, None, None).expect("render");
        assert!(out.seen.iter().all(|&s| s == 0));
    }

    #[test]
    fn views_are_kept_by_separation_and_bad_sizes_are_refused() {
        let proxy = wall();
        let mut views =
            BackgroundViews::new(64, 48, proxy.clone(), 2, 5f64.to_radians()).expect("views");
        let photo: Vec<u8> = (0..64 * 48 * 4).map(|i| (i % 251) as u8).collect();
        let f = RgbaView::new("f", 64, 48, &photo).expect("f");
        let free = vec![0u8; 64 * 48];
        let a = camera([1.5, 0.0, 1.0], [0.0, 0.0, 1.0]);
        let near = camera([1.5, 0.0, 1.0], [0.0, 0.05, 1.0]);
        let far = camera([1.5, 0.0, 1.0], [0.0, 0.5, 1.0]);
        let farther = camera([1.5, 0.0, 1.0], [0.0, -0.5, 1.0]);
        assert!(views.offer(&a, &f, &free, 0.0).expect("a"));
        assert!(
            !views.offer(&near, &f, &free, 0.1).expect("near"),
            "2 deg away"
        );
        assert!(views.offer(&far, &f, &free, 0.2).expect("far"));
        assert!(views.offer(&farther, &f, &free, 0.3).expect("farther"));
        assert_eq!(views.len(), 2, "the oldest went");
        assert_eq!(views.times(), vec![0.2, 0.3]);
        assert_eq!(views.offered(), 4);
        assert!(views.nearest_angle(&a).expect("angle") > 0.3);
        // A pinned view stays when the others come and go.
        let mut pinned =
            BackgroundViews::new(64, 48, proxy.clone(), 2, 5f64.to_radians()).expect("views");
        pinned.set_photograph(&a, &f, -1.0).expect("pinned");
        for (i, cam) in [&far, &farther, &near].into_iter().enumerate() {
            pinned.offer(cam, &f, &free, i as f64).expect("offer");
        }
        assert_eq!(pinned.times(), vec![-1.0, 1.0]);
        // A new photograph replaces the old one, wherever it was taken.
        pinned.set_photograph(&far, &f, -2.0).expect("again");
        assert_eq!(pinned.times(), vec![1.0, -2.0]);
        let mut bad = a;
        bad.world_from_camera.translation.vector.x = f64::NAN;
        assert!(pinned.offer(&bad, &f, &free, 5.0).is_err());
        assert!(pinned.set_photograph(&bad, &f, 5.0).is_err());
        let small = RgbaView::new("s", 32, 24, &photo[..32 * 24 * 4]).expect("s");
        assert!(views.offer(&a, &small, &free, 0.4).is_err());
        assert!(
            views
                .render(
                    &camera([1.0, 0.0, 1.0], [0.0, 0.0, 1.0]),
                    Some(vec![0u8; 3]),
                    None
                )
                .is_err()
        );
        assert!(BackgroundViews::new(64, 48, proxy.clone(), 0, 0.0).is_err());
        assert!(BackgroundViews::new(64, 48, proxy, 2, f64::NAN).is_err());
    }

    #[test]
    fn a_blank_frame_is_not_a_view() {
        // The live preview's first frame is black (the simulated camera has not rendered yet):
        // kept as a view, it darkened H by half wherever Alice looked back the same way.
        let mut views = BackgroundViews::new(64, 48, wall(), 4, 0.0).expect("views");
        let cam = camera([1.5, 0.0, 1.0], [0.0, 0.0, 1.0]);
        let free = vec![0u8; 64 * 48];
        let black = vec![0u8; 64 * 48 * 4];
        let f = RgbaView::new("black", 64, 48, &black).expect("f");
        assert!(!views.offer(&cam, &f, &free, 0.0).expect("offered"));
        // One colour with a sensor's noise (σ 1.5 levels, as the simulated camera adds) is as
        // blank; covered pixels do not count.
        let mut rng = crate::rng::Rng::stream(1, 2);
        let mut grey: Vec<u8> = (0..64 * 48 * 4)
            .map(|_| (128.0 + 1.5 * rng.gaussian()).round() as u8)
            .collect();
        grey[4 * 100] = 0;
        let mut covered = vec![0u8; 64 * 48];
        covered[100] = 1;
        let f = RgbaView::new("grey", 64, 48, &grey).expect("f");
        assert!(!views.offer(&cam, &f, &covered, 0.1).expect("offered"));
        assert_eq!((views.len(), views.offered(), views.blank()), (0, 2, 2));
        // The room is a view.
        let room = photograph(&wall(), &cam);
        let f = RgbaView::new("room", 64, 48, &room).expect("f");
        assert!(views.offer(&cam, &f, &free, 0.2).expect("offered"));
        assert_eq!(views.blank(), 2);
    }
}
