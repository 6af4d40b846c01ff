// Resize, NCHW, height and width. mode 0: nearest with ONNX `asymmetric` coordinates and
// `floor` rounding (source = floor(out / scale), clamped). Modes 1-4 bilinear, the source
// coordinate by ONNX's transformation (1 half_pixel, 2 align_corners, 3 asymmetric,
// 4 pytorch_half_pixel), clamped to the input, then the two neighbours on each axis.
struct Params { planes: u32, h: u32, w: u32, oh: u32, ow: u32, fy: f32, fx: f32, mode: u32 }

@group(0) @binding(0) var<storage, read> x: array<f32>;
@group(0) @binding(1) var<storage, read_write> y: array<f32>;
@group(0) @binding(2) var<uniform> p: Params;
// Element offsets into the bound buffers: x = first input, y = second input, z = output.
@group(0) @binding(3) var<uniform> off: vec4<u32>;

fn source(o: u32, scale: f32, len_in: u32, len_out: u32) -> f32 {
    let v = f32(o);
    switch p.mode {
        case 2u: {
            if (len_out > 1u) {
                return v * f32(len_in - 1u) / f32(len_out - 1u);
            }
            return 0.0;
        }
        case 3u: { return v / scale; }
        case 4u: {
            if (len_out > 1u) {
                return (v + 0.5) / scale - 0.5;
            }
            return 0.0;
        }
        default: { return (v + 0.5) / scale - 0.5; }
    }
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let idx = gid.x + gid.y * nwg.x * 64u;
    if (idx >= p.planes * p.oh * p.ow) {
        return;
    }
    let ox = idx % p.ow;
    let oy = (idx / p.ow) % p.oh;
    let plane = idx / (p.ow * p.oh);
    let base = off.x + plane * p.h * p.w;
    if (p.mode == 0u) {
        let iy = min(u32(floor(f32(oy) / p.fy)), p.h - 1u);
        let ix = min(u32(floor(f32(ox) / p.fx)), p.w - 1u);
        y[off.z + idx] = x[base + iy * p.w + ix];
        return;
    }
    let sy = clamp(source(oy, p.fy, p.h, p.oh), 0.0, f32(p.h - 1u));
    let sx = clamp(source(ox, p.fx, p.w, p.ow), 0.0, f32(p.w - 1u));
    let y0 = u32(floor(sy));
    let x0 = u32(floor(sx));
    let y1 = min(y0 + 1u, p.h - 1u);
    let x1 = min(x0 + 1u, p.w - 1u);
    let wy = sy - f32(y0);
    let wx = sx - f32(x0);
    let a = x[base + y0 * p.w + x0];
    let b = x[base + y0 * p.w + x1];
    let c = x[base + y1 * p.w + x0];
    let d = x[base + y1 * p.w + x1];
    let top = a + (b - a) * wx;
    let bottom = c + (d - c) * wx;
    y[off.z + idx] = top + (bottom - top) * wy;
}
