// Dense convolution (one group) as an implicit GEMM, NCHW: Y[m, p] = sum_k W[m, k] * B[k, p]
// with k = (ic, ky, kx) and B the input patch of output pixel p, never materialised (im2col
// addresses are computed while loading). Each workgroup of 256 invocations computes a tile
// of TM output channels x TN output pixels, each invocation a 4x4 block in registers; K runs
// in steps of 16 through workgroup memory. Bias and an activation are fused into the store.
// 1x1 convolutions (the pointwise half of YOLOX's blocks) are the same GEMM with trivial
// addressing. Tiles: 64x64, 32x128 for layers of at most 32 channels, 16x256 for at most 16
// (a stem), chosen by the host, which rewrites the two constants below.
const TM: u32 = 64u;
const TN: u32 = 64u;
const WX: u32 = TN / 4u;
const WY: u32 = TM / 4u;
struct Params {
    c: u32, h: u32, w: u32, m: u32,
    oh: u32, ow: u32, kh: u32, kw: u32,
    sh: u32, sw: u32, ph: u32, pw: u32,
    dh: u32, dw: u32, act: u32, k: u32,
}

@group(0) @binding(0) var<storage, read> x: array<f32>;
@group(0) @binding(1) var<storage, read> wt: array<f32>;
@group(0) @binding(2) var<storage, read> bias: array<f32>;
@group(0) @binding(3) var<storage, read_write> y: array<f32>;
@group(0) @binding(4) var<uniform> u: Params;
// Element offsets into the bound buffers: x = input, z = output.
@group(0) @binding(5) var<uniform> off: vec4<u32>;

// Weights tile [16 k][TM m] and input tile [16 k][TN p].
var<workgroup> ta: array<f32, 16u * TM>;
var<workgroup> tb: array<f32, 16u * TN>;

@compute @workgroup_size(WX, WY)
fn main(@builtin(local_invocation_id) lid: vec3<u32>, @builtin(workgroup_id) wid: vec3<u32>) {
    let tid = lid.y * WX + lid.x;
    let npix = u.oh * u.ow;
    let p0 = wid.x * TN;
    let m0 = wid.y * TM;
    let batch = wid.z;
    let khw = u.kh * u.kw;
    let xb = off.x + batch * u.c * u.h * u.w;
    var acc: array<f32, 16>;
    for (var k0 = 0u; k0 < u.k; k0 += 16u) {
        // Weights: consecutive invocations read consecutive k of one output channel.
        for (var r = 0u; r < TM / 16u; r++) {
            let e = tid + r * 256u;
            let ka = e % 16u;
            let ma = e / 16u;
            var a = 0.0;
            if (m0 + ma < u.m && k0 + ka < u.k) {
                a = wt[(m0 + ma) * u.k + k0 + ka];
            }
            ta[ka * TM + ma] = a;
        }
        // Input patch: consecutive invocations read consecutive output pixels.
        for (var r = 0u; r < TN / 16u; r++) {
            let e = tid + r * 256u;
            let kb = e / TN;
            let pb = e % TN;
            var v = 0.0;
            let gp = p0 + pb;
            let gk = k0 + kb;
            if (gp < npix && gk < u.k) {
                let ic = gk / khw;
                let rem = gk % khw;
                let ky = rem / u.kw;
                let kx = rem % u.kw;
                let oy = gp / u.ow;
                let ox = gp % u.ow;
                let iy = i32(oy * u.sh + ky * u.dh) - i32(u.ph);
                let ix = i32(ox * u.sw + kx * u.dw) - i32(u.pw);
                if (iy >= 0 && iy < i32(u.h) && ix >= 0 && ix < i32(u.w)) {
                    v = x[xb + (ic * u.h + u32(iy)) * u.w + u32(ix)];
                }
            }
            tb[kb * TN + pb] = v;
        }
        workgroupBarrier();
        for (var kk = 0u; kk < 16u; kk++) {
            var av: array<f32, 4>;
            var bv: array<f32, 4>;
            for (var i = 0u; i < 4u; i++) {
                av[i] = ta[kk * TM + lid.y + WY * i];
                bv[i] = tb[kk * TN + lid.x + WX * i];
            }
            for (var i = 0u; i < 4u; i++) {
                for (var j = 0u; j < 4u; j++) {
                    acc[i * 4u + j] += av[i] * bv[j];
                }
            }
        }
        workgroupBarrier();
    }
    for (var i = 0u; i < 4u; i++) {
        let m = m0 + lid.y + WY * i;
        if (m >= u.m) {
            continue;
        }
        for (var j = 0u; j < 4u; j++) {
            let pix = p0 + lid.x + WX * j;
            if (pix >= npix) {
                continue;
            }
            var v = acc[i * 4u + j] + bias[m];
            switch u.act {
                case 1u: { v = v / (1.0 + exp(-v)); }
                case 2u: { v = 1.0 / (1.0 + exp(-v)); }
                case 3u: { v = max(v, 0.0); }
                default: {}
            }
            y[off.z + (batch * u.m + m) * npix + pix] = v;
        }
    }
}
