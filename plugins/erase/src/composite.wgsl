// Composite pass: the background panel over the live panel, alpha = alpha_H * feathered M(t),
// blended in the camera's 8-bit encoding. Same arithmetic as avatarm_core::dr::composite.
#import bevy_pbr::forward_io::VertexOutput

struct CompositeParams {
    gain: vec4<f32>,
    offset: vec4<f32>,
    size: vec2<u32>,
    alpha_h: f32,
    feather: u32,
}

@group(#{MATERIAL_BIND_GROUP}) @binding(0) var<uniform> params: CompositeParams;
@group(#{MATERIAL_BIND_GROUP}) @binding(1) var live: texture_2d<f32>;
@group(#{MATERIAL_BIND_GROUP}) @binding(2) var background: texture_2d<f32>;
@group(#{MATERIAL_BIND_GROUP}) @binding(3) var mask: texture_2d<f32>;

fn srgb_to_linear(s: vec3<f32>) -> vec3<f32> {
    let lo = s / 12.92;
    let hi = pow((s + 0.055) / 1.055, vec3<f32>(2.4));
    return select(hi, lo, s <= vec3<f32>(0.04045));
}

@fragment
fn fragment(in: VertexOutput) -> @location(0) vec4<f32> {
    let p = vec2<i32>(floor(in.position.xy));
    let f = i32(params.feather);
    let last = vec2<i32>(params.size) - vec2<i32>(1);
    var count = 0u;
    for (var dy = -f; dy <= f; dy++) {
        for (var dx = -f; dx <= f; dx++) {
            let q = clamp(p + vec2<i32>(dx, dy), vec2<i32>(0), last);
            if textureLoad(mask, q, 0).r > 0.5 {
                count += 1u;
            }
        }
    }
    let side = f32(2 * f + 1);
    let a = f32(count) / (side * side);
    let i = textureLoad(live, p, 0).rgb;
    let h = clamp(params.gain.rgb * textureLoad(background, p, 0).rgb + params.offset.rgb,
                  vec3<f32>(0.0), vec3<f32>(1.0));
    let t = a * params.alpha_h;
    let v = clamp(i + (h - i) * t, vec3<f32>(0.0), vec3<f32>(1.0));
    // The target stores sRGB: write the linear value whose encoding is v.
    return vec4<f32>(srgb_to_linear(v), 1.0);
}
