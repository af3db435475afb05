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
mod tests;
