// Direct 2-D convolution, NCHW, one invocation per output element; groups, strides, padding,
// dilation; bias and an activation fused into the store.
struct Params {
    c: u32, h: u32, w: u32, m: u32,
    oh: u32, ow: u32, kh: u32, kw: u32,
    sh: u32, sw: u32, ph: u32, pw: u32,
    dh: u32, dw: u32, act: u32, k: u32,
    n: u32, group: u32, pad0: u32, pad1: u32,
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
    let cg = p.c / p.group;
    let g = oc / (p.m / p.group);
    var acc = bias[oc];
    for (var icg = 0u; icg < cg; icg++) {
        let ic = g * cg + icg;
        for (var ky = 0u; ky < p.kh; ky++) {
            let iy = i32(oy * p.sh + ky * p.dh) - i32(p.ph);
            if (iy < 0 || iy >= i32(p.h)) {
                continue;
            }
            for (var kx = 0u; kx < p.kw; kx++) {
                let ix = i32(ox * p.sw + kx * p.dw) - i32(p.pw);
                if (ix < 0 || ix >= i32(p.w)) {
                    continue;
                }
                acc += wt[((oc * cg + icg) * p.kh + ky) * p.kw + kx] * x[off.x + ((b * p.c + ic) * p.h + u32(iy)) * p.w + u32(ix)];
            }
        }
    }
    switch p.act {
        case 1u: { acc = acc / (1.0 + exp(-acc)); }
        case 2u: { acc = 1.0 / (1.0 + exp(-acc)); }
        case 3u: { acc = max(acc, 0.0); }
        default: {}
    }
    y[off.z + idx] = acc;
}
