// Flat silhouettes (avatarm_twin::flat): every part in one grey level, through a pinhole
// camera, depth-tested, nothing else. World position and clip position are computed as Bevy's
// mesh shader does (world = world_from_local * p, clip = clip_from_world * world).

struct View {
    clip_from_world: mat4x4<f32>,
}

struct Draw {
    world_from_local: mat4x4<f32>,
    // x: the part's grey level (0..1); yzw unused.
    level: vec4<f32>,
}

@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var<storage, read> draws: array<Draw>;

struct VertexOutput {
    @builtin(position) position: vec4<f32>,
    @location(0) @interpolate(flat) level: f32,
}

@vertex
fn vertex(@location(0) position: vec3<f32>, @builtin(instance_index) draw: u32) -> VertexOutput {
    let d = draws[draw];
    let world = d.world_from_local * vec4<f32>(position, 1.0);
    var out: VertexOutput;
    out.position = view.clip_from_world * world;
    out.level = d.level.x;
    return out;
}

@fragment
fn fragment(in: VertexOutput) -> @location(0) vec4<f32> {
    return vec4<f32>(in.level, 0.0, 0.0, 1.0);
}
