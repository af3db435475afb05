// The preview's mask overlay: the panel's image with the mask M(t) tinted over it.
#import bevy_ui::ui_vertex_output::UiVertexOutput

@group(1) @binding(0) var<uniform> tint: vec4<f32>;
@group(1) @binding(1) var panel_image: texture_2d<f32>;
@group(1) @binding(2) var panel_sampler: sampler;
@group(1) @binding(3) var mask_image: texture_2d<f32>;
@group(1) @binding(4) var mask_sampler: sampler;
// x = 1: the image has one channel (the R8 mask), shown in grey.
@group(1) @binding(5) var<uniform> grey: vec4<f32>;

@fragment
fn fragment(in: UiVertexOutput) -> @location(0) vec4<f32> {
    let s = textureSample(panel_image, panel_sampler, in.uv);
    let c = select(s.rgb, vec3<f32>(s.r), grey.x > 0.5);
    let m = textureSample(mask_image, mask_sampler, in.uv).r;
    let a = select(0.0, tint.a, m > 0.5);
    return vec4<f32>(mix(c, tint.rgb, a), 1.0);
}
