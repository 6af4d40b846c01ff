// Pooling, NCHW: mode 0 max (padding excluded), 1 average over the pixels inside, 2 average
// counting the padding (ONNX `count_include_pad`).
struct Params {
    planes: u32, h: u32, w: u32, oh: u32,
    ow: u32, kh: u32, kw: u32, sh: u32,
    sw: u32, ph: u32, pw: u32, mode: u32,
}

@group(0) @binding(0) var<storage, read> x: array<f32>;
@group(0) @binding(1) var<storage, read_write> y: array<f32>;
@group(0) @binding(2) var<uniform> p: Params;
// Element offsets into the bound buffers: x = first input, y = second input, z = output.
@group(0) @binding(3) var<uniform> off: vec4<u32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let idx = gid.x + gid.y * nwg.x * 64u;
    if (idx >= p.planes * p.oh * p.ow) {
        return;
    }
    let ox = idx % p.ow;
    let oy = (idx / p.ow) % p.oh;
    let plane = idx / (p.ow * p.oh);
    var acc = -3.4028235e38;
    if (p.mode != 0u) {
        acc = 0.0;
    }
    var count = 0u;
    for (var ky = 0u; ky < p.kh; ky++) {
        let iy = i32(oy * p.sh + ky) - i32(p.ph);
        if (iy < 0 || iy >= i32(p.h)) {
            continue;
        }
        for (var kx = 0u; kx < p.kw; kx++) {
            let ix = i32(ox * p.sw + kx) - i32(p.pw);
            if (ix < 0 || ix >= i32(p.w)) {
                continue;
            }
            let v = x[off.x + (plane * p.h + u32(iy)) * p.w + u32(ix)];
            if (p.mode == 0u) {
                acc = max(acc, v);
            } else {
                acc += v;
            }
            count += 1u;
        }
    }
    if (p.mode == 1u) {
        acc = acc / f32(max(count, 1u));
    } else if (p.mode == 2u) {
        acc = acc / f32(p.kh * p.kw);
    }
    y[off.z + idx] = acc;
}
