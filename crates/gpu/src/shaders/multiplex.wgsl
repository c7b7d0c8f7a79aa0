// y = Σ_k z_k ⊙ s̃_k per pixel: the monochrome camera sums the modulated images
// (crates/twin/src/multiplex.rs does the same on the CPU, k ascending from 0 as here).

struct Params {
    npx: u32,
    planes: u32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<storage, read> z: array<f32>;
@group(0) @binding(1) var<storage, read> s: array<f32>;
@group(0) @binding(2) var<storage, read_write> y: array<f32>;
@group(0) @binding(3) var<uniform> mp: Params;

@compute @workgroup_size(256)
fn multiplex(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let n = mp.npx;
    let p = gid.x + gid.y * nwg.x * 256u;
    if p >= n {
        return;
    }
    var acc = 0.0;
    for (var k = 0u; k < mp.planes; k++) {
        acc += z[k * n + p] * s[k * n + p];
    }
    y[p] = acc;
}
