// The erase passes (avatarm_erase::passes): threshold, square dilation, feathering and the
// composite, each a full-target triangle with no camera, the same arithmetic as
// avatarm_core::dr (threshold_mask, dilate, feather_alpha, composite) so that GPU = CPU.
//
// r = dilate + feather (the mask's radius), f = feather. Separable windows (a square max is a
// row max then a column max; a box sum is a row sum then a column sum), edges repeated:
//   r = 0:         composite_threshold                     (1 pass: threshold inline)
//   r > 0, f = 0:  dilate_rows -> composite_dilated        (2 passes: column max inline)
//   f > 0:         dilate_rows -> dilate_columns -> feather_rows -> composite_feathered
// Through a lens (params.lens = 1) the twin's render is the pinhole view of a lens map and each
// pixel reads the texel its ray lands on (avatarm_core::vision::distortion::DistortionMap).
// A pass that writes M(t) writes it as 0/1 into an R8 target; Ĩ(t) is written through an
// Rgba8Unorm view of its sRGB image, so its bytes are the 8-bit values themselves.
#import bevy_core_pipeline::fullscreen_vertex_shader::FullscreenVertexOutput

struct EraseParams {
    // Inclusive 8-bit ranges of R, G, B, alpha (the paper's uniformity predicate).
    lo: vec4<f32>,
    hi: vec4<f32>,
    // The background's photometric model (w unused).
    gain: vec4<f32>,
    offset: vec4<f32>,
    raw_size: vec2<u32>,
    size: vec2<u32>,
    radius: i32,
    feather: i32,
    alpha_h: f32,
    // 1: the twin's render is a lens map's pinhole view, read at the map's texel per pixel.
    lens: u32,
}

@group(0) @binding(0) var<uniform> params: EraseParams;
// The mask twin's flat render: one grey channel, read as (v, v, v, 255).
@group(0) @binding(1) var raw_twin: texture_2d<f32>;
@group(0) @binding(2) var live: texture_2d<f32>;
@group(0) @binding(3) var background: texture_2d<f32>;
// The previous pass's output (row maxima, the mask, or row sums).
@group(0) @binding(4) var previous: texture_2d<f32>;
// Per frame pixel, the render's texel its ray lands on through the lens (65535: none).
@group(0) @binding(5) var lens_map: texture_2d<u32>;

fn clamped(p: vec2<i32>) -> vec2<i32> {
    return clamp(p, vec2<i32>(0), vec2<i32>(params.size) - vec2<i32>(1));
}

// M before dilation at a full-size pixel: the raw texel its ray lands on (through the lens),
// else its nearest raw texel by scale, in the ranges.
fn is_robot(p: vec2<i32>) -> bool {
    let q = vec2<u32>(clamped(p));
    var r = ((q * 2u + 1u) * params.raw_size) / (2u * params.size);
    if params.lens != 0u {
        r = textureLoad(lens_map, vec2<i32>(q), 0).rg;
        if r.x == 65535u {
            return false;
        }
    }
    let v = round(textureLoad(raw_twin, vec2<i32>(r), 0).r * 255.0);
    let px = vec4<f32>(v, v, v, 255.0);
    return all(px >= params.lo) && all(px <= params.hi);
}

fn previous_at(p: vec2<i32>) -> f32 {
    return textureLoad(previous, clamped(p), 0).r;
}

// Ĩ = I + (H' − I)·α_H·a, H' = clamp(gain·H + offset), per channel in the camera's encoding.
fn composite(p: vec2<i32>, a: f32) -> vec4<f32> {
    let i = textureLoad(live, p, 0).rgb;
    let h = clamp(params.gain.rgb * textureLoad(background, p, 0).rgb + params.offset.rgb,
                  vec3<f32>(0.0), vec3<f32>(1.0));
    let t = a * params.alpha_h;
    return vec4<f32>(clamp(i + (h - i) * t, vec3<f32>(0.0), vec3<f32>(1.0)), 1.0);
}

struct Erased {
    @location(0) erased: vec4<f32>,
    @location(1) mask: vec4<f32>,
}

fn erased(p: vec2<i32>, m: f32) -> Erased {
    var out: Erased;
    out.erased = composite(p, m);
    out.mask = vec4<f32>(m, 0.0, 0.0, 1.0);
    return out;
}

fn pixel(in: FullscreenVertexOutput) -> vec2<i32> {
    return vec2<i32>(floor(in.position.xy));
}

@fragment
fn composite_threshold(in: FullscreenVertexOutput) -> Erased {
    let p = pixel(in);
    return erased(p, select(0.0, 1.0, is_robot(p)));
}

@fragment
fn dilate_rows(in: FullscreenVertexOutput) -> @location(0) vec4<f32> {
    let p = pixel(in);
    for (var d = -params.radius; d <= params.radius; d++) {
        if is_robot(p + vec2<i32>(d, 0)) {
            return vec4<f32>(1.0, 0.0, 0.0, 1.0);
        }
    }
    return vec4<f32>(0.0, 0.0, 0.0, 1.0);
}

fn column_max(p: vec2<i32>) -> f32 {
    for (var d = -params.radius; d <= params.radius; d++) {
        if previous_at(p + vec2<i32>(0, d)) > 0.5 {
            return 1.0;
        }
    }
    return 0.0;
}

@fragment
fn composite_dilated(in: FullscreenVertexOutput) -> Erased {
    let p = pixel(in);
    return erased(p, column_max(p));
}

@fragment
fn dilate_columns(in: FullscreenVertexOutput) -> @location(0) vec4<f32> {
    return vec4<f32>(column_max(pixel(in)), 0.0, 0.0, 1.0);
}

// Row sums of the mask over (2f+1) pixels: integers, exact in an R16Float target.
@fragment
fn feather_rows(in: FullscreenVertexOutput) -> @location(0) vec4<f32> {
    let p = pixel(in);
    var count = 0.0;
    for (var d = -params.feather; d <= params.feather; d++) {
        if previous_at(p + vec2<i32>(d, 0)) > 0.5 {
            count += 1.0;
        }
    }
    return vec4<f32>(count, 0.0, 0.0, 1.0);
}

// a = the mask's mean over the (2f+1)² window: the column sum of the row sums over the area.
@fragment
fn composite_feathered(in: FullscreenVertexOutput) -> @location(0) vec4<f32> {
    let p = pixel(in);
    var count = 0.0;
    for (var d = -params.feather; d <= params.feather; d++) {
        count += round(previous_at(p + vec2<i32>(0, d)));
    }
    let side = f32(2 * params.feather + 1);
    return composite(p, count / (side * side));
}
