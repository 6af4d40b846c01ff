// Transposed 2-D convolution, NCHW, one invocation per output element, gathering the input
// pixels whose scatter reaches it: groups, strides, dilations, begin padding; weights
// C_in x (M / group) x kH x kW; bias fused.
struct Params {
    c: u32, h: u32, w: u32, m: u32,
    oh: u32, ow: u32, kh: u32, kw: u32,
    sh: u32, sw: u32, ph: u32, pw: u32,
    dh: u32, dw: u32, n: u32, group: u32,
}

@group(0) @binding(0) var<storage, read> x: array<f32>;
@group(0) @binding(1) var<storage, read> wt: array<f32>;
@group(0) @binding(2) var<storage, read> bias: array<f32>;
@group(0) @binding(3) var<storage, read_write> y: array<f32>;
@group(0) @binding(4) var<uniform> p: Params;
// Element offsets into the bound buffers: x = first input, y = second input, z = output.
@group(0) @binding(5) var<uniform> off: vec4<u32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let idx = gid.x + gid.y * nwg.x * 64u;
    if (idx >= p.n * p.m * p.oh * p.ow) {
        return;
    }
    let ox = idx % p.ow;
    let oy = (idx / p.ow) % p.oh;
    let oc = (idx / (p.ow * p.oh)) % p.m;
    let b = idx / (p.ow * p.oh * p.m);
    let mg = p.m / p.group;
    let cg = p.c / p.group;
    let g = oc / mg;
    let ocg = oc % mg;
    var acc = bias[oc];
    for (var ky = 0u; ky < p.kh; ky++) {
        // Output row oy = iy * sh + ky * dh - ph.
        let ty = i32(oy + p.ph) - i32(ky * p.dh);
        if (ty < 0 || ty % i32(p.sh) != 0) {
            continue;
        }
        let iy = u32(ty) / p.sh;
        if (iy >= p.h) {
            continue;
        }
        for (var kx = 0u; kx < p.kw; kx++) {
            let tx = i32(ox + p.pw) - i32(kx * p.dw);
            if (tx < 0 || tx % i32(p.sw) != 0) {
                continue;
            }
            let ix = u32(tx) / p.sw;
            if (ix >= p.w) {
                continue;
            }
            for (var icg = 0u; icg < cg; icg++) {
                let ic = g * cg + icg;
                let xv = x[off.x + ((b * p.c + ic) * p.h + iy) * p.w + ix];
                acc += xv * wt[((ic * mg + ocg) * p.kh + ky) * p.kw + kx];
            }
        }
    }
    y[off.z + idx] = acc;
}
