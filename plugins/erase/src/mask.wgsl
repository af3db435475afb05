// Threshold pass: the twin's white-on-black render -> binary mask M(t), dilated by a square
// window. Same arithmetic as avatarm_core::dr::threshold_mask.
#import bevy_pbr::forward_io::VertexOutput

struct MaskParams {
    // Inclusive 8-bit ranges of R, G, B, alpha.
    lo: vec4<f32>,
    hi: vec4<f32>,
    raw_size: vec2<u32>,
    full_size: vec2<u32>,
    radius: u32,
}

@group(#{MATERIAL_BIND_GROUP}) @binding(0) var<uniform> params: MaskParams;
@group(#{MATERIAL_BIND_GROUP}) @binding(1) var raw_twin: texture_2d<f32>;

// The 8-bit value an sRGB texture stored for a sampled linear value.
fn srgb_byte(linear: f32) -> f32 {
    var s: f32;
    if linear <= 0.0031308 {
        s = linear * 12.92;
    } else {
        s = 1.055 * pow(linear, 1.0 / 2.4) - 0.055;
    }
    return round(clamp(s, 0.0, 1.0) * 255.0);
}

fn is_robot(p: vec2<i32>) -> bool {
    let q = vec2<u32>(clamp(p, vec2<i32>(0), vec2<i32>(params.full_size) - vec2<i32>(1)));
    // Nearest raw texel, by integer arithmetic as on the CPU.
    let r = ((q * 2u + 1u) * params.raw_size) / (2u * params.full_size);
    let c = textureLoad(raw_twin, vec2<i32>(r), 0);
    let b = vec4<f32>(srgb_byte(c.r), srgb_byte(c.g), srgb_byte(c.b), round(c.a * 255.0));
    return all(b >= params.lo) && all(b <= params.hi);
}

@fragment
fn fragment(in: VertexOutput) -> @location(0) vec4<f32> {
    let p = vec2<i32>(floor(in.position.xy));
    let r = i32(params.radius);
    for (var dy = -r; dy <= r; dy++) {
        for (var dx = -r; dx <= r; dx++) {
            if is_robot(p + vec2<i32>(dx, dy)) {
                return vec4<f32>(1.0, 1.0, 1.0, 1.0);
            }
        }
    }
    return vec4<f32>(0.0, 0.0, 0.0, 1.0);
}
