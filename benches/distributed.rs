//! What an edge between machines costs, side by side with the in-process edge, in
//! one run: one-way latency per message (small scalars, a 640×480 colour image) over zenoh on
//! loopback (two sessions in this process, so one clock: encoding, TCP, decoding) against the
//! in-process handoff of an `Arc<Message>` through a tokio channel (what an engine edge does);
//! then the default graph (`graphs/default.yaml`) split over two `dynaflow run --machine`
//! processes (its detector on the second) against the same graph in one process, frames per
//! second, recording off.
//!
//! `cargo bench --features zenoh --bench distributed` (add `-- N`: messages per kind, default 300).

use std::sync::Arc;
use std::time::{Duration, Instant};

use dynaflow_engine::msg::{Body, Header, Image, Message, PixelFormat, Scalars};
use dynaflow_engine::runtime::remote::{Frame, Wire, decode_frame, encode_frame};
use dynaflow_engine::{LoadRequest, load_str};
use dynaflow_net::ZenohWire;

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0").and_then(|l| l.local_addr()).map(|a| a.port()).expect("a free port")
}

fn percentile(v: &mut [f64], q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

fn messages() -> Vec<(&'static str, Message)> {
    let header = Header { seq: 0, stamp: 0.0, frame_id: Arc::from("camera") };
    let scalars = Body::Scalars(Scalars { values: vec![("frame".into(), 1.0), ("time".into(), 0.033)] });
    let pixels: Vec<u8> = (0..640 * 480 * 3).map(|i| (i * 7 % 251) as u8).collect();
    let image = Body::Image(Image { width: 640, height: 480, format: PixelFormat::Rgb8, data: pixels });
    vec![("scalars", Message::new(header.clone(), scalars)), ("image 640x480 rgb8", Message::new(header, image))]
}

fn main() {
    let n: usize = std::env::args().skip(1).find_map(|a| a.parse().ok()).unwrap_or(300);
    let rt = tokio::runtime::Builder::new_multi_thread().enable_all().build().expect("runtime");
    println!("one-way latency per message, {n} messages each, sent one at a time (p50 / p95 µs):");
    println!("  {:<22} {:>22} {:>22} {:>9}", "message", "in-process edge", "zenoh loopback", "bytes");
    let (pa, pb) = (free_port(), free_port());
    let text = format!(
        "name: wire_bench\nmachines:\n  a: {{ endpoint: \"tcp/127.0.0.1:{pa}\" }}\n  b: {{ endpoint: \"tcp/127.0.0.1:{pb}\" }}\nnodes:\n  camera: {{ op: testing.test_pattern }}\n  sink: {{ op: passthrough, machine: b, in: {{ input: camera.tick }} }}\n"
    );
    let loaded = load_str("bench.yaml", &text, None, &dynaflow_engine::testing::registry(), &LoadRequest::default());
    let graph = loaded.graph.expect("bench graph");
    rt.block_on(async {
        let timeout = Duration::from_secs(20);
        let (a, b) =
            futures_join(ZenohWire::open(&graph, "a", timeout, None), ZenohWire::open(&graph, "b", timeout, None))
                .await;
        let (a, b) = (a.expect("machine a"), b.expect("machine b"));
        let mut rx = b.subscriber("camera/tick", "a").await.expect("subscriber");
        let (ra, rb) = futures_join(a.ready(), b.ready()).await;
        ra.and(rb).expect("ready");
        let to = [Arc::from("b")];
        let tx = a.publisher("camera/tick", &to).await.expect("publisher");
        for (name, msg) in messages() {
            // In-process: the Arc handed through a channel, as an engine edge hands it on.
            let (ctx, mut crx) = tokio::sync::mpsc::channel::<Arc<Message>>(4);
            let shared = Arc::new(msg.clone());
            let mut local = Vec::with_capacity(n);
            for _ in 0..n {
                let t0 = Instant::now();
                ctx.send(shared.clone()).await.expect("send");
                let got = crx.recv().await.expect("recv");
                local.push(t0.elapsed().as_secs_f64() * 1e6);
                assert_eq!(got.header.seq, 0);
            }
            let mut wire = Vec::with_capacity(n);
            let mut bytes = 0;
            for seq in 0..n as u64 {
                let t0 = Instant::now();
                let frame = encode_frame(seq, Some(&msg));
                bytes = frame.len();
                tx.send(frame).await.expect("zenoh send");
                let got = rx.recv().await.expect("zenoh recv");
                let Ok(Frame::Envelope(s, Some(m))) = decode_frame(&got) else { panic!("bad frame") };
                wire.push(t0.elapsed().as_secs_f64() * 1e6);
                assert!(s == seq && m.digest() == msg.digest(), "the message arrives intact");
            }
            println!(
                "  {:<22} {:>10.1} / {:>9.1} {:>10.1} / {:>9.1} {:>9}",
                name,
                percentile(&mut local, 0.5),
                percentile(&mut local, 0.95),
                percentile(&mut wire, 0.5),
                percentile(&mut wire, 0.95),
                bytes
            );
        }
        a.finish().await;
        b.finish().await;
    });
    drop(rt);
    split_default_graph();
}

async fn futures_join<A: std::future::Future, B: std::future::Future>(a: A, b: B) -> (A::Output, B::Output) {
    tokio::join!(a, b)
}

/// The default graph in one process and split over two (its detector on `server`), recording
/// off: frames per second of each, best of 3 alternating.
fn split_default_graph() {
    let repo = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let exe = env!("CARGO_BIN_EXE_dynaflow");
    let dir = std::env::temp_dir().join(format!("dynaflow-bench-split-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let mut text = std::fs::read_to_string(repo.join("graphs/default.yaml")).expect("default graph");
    let at = "  detector:\n    op: detect\n";
    assert!(text.contains(at), "graphs/default.yaml changed");
    text = text.replace(at, &format!("{at}    machine: server\n"));
    text += &format!(
        "\nmachines:\n  robot: {{ endpoint: \"tcp/127.0.0.1:{}\" }}\n  server: {{ endpoint: \"tcp/127.0.0.1:{}\" }}\n",
        free_port(),
        free_port()
    );
    let split = dir.join("default_split.yaml");
    std::fs::write(&split, text).expect("write graph");
    let run = |graph: &std::path::Path, machine: Option<&str>, out: &str| {
        let mut c = std::process::Command::new(exe);
        c.arg("run").arg(graph).args(["--record", "none", "--no-progress", "--out"]).arg(dir.join(out));
        if let Some(m) = machine {
            c.args(["--machine", m]);
        }
        c.stdout(std::process::Stdio::null()).stderr(std::process::Stdio::null());
        c.spawn().expect("dynaflow")
    };
    let (mut one, mut two) = (f64::INFINITY, f64::INFINITY);
    for _ in 0..3 {
        let t0 = Instant::now();
        let status = run(&repo.join("graphs/default.yaml"), None, "one").wait().expect("one process");
        assert!(status.success(), "one-process run failed");
        one = one.min(t0.elapsed().as_secs_f64());
        let t0 = Instant::now();
        let server = run(&split, Some("server"), "server");
        let robot = run(&split, Some("robot"), "robot");
        let (r, s) = (robot.wait_with_output().expect("robot"), server.wait_with_output().expect("server"));
        assert!(r.status.success() && s.status.success(), "split run failed");
        two = two.min(t0.elapsed().as_secs_f64());
    }
    let frames = 300.0;
    println!("\nthe default graph ({frames} frames, recording off), process wall time, best of 3 alternating:");
    println!("  one process:                    {:>6.2} s  {:>5.1} frames/s", one, frames / one);
    println!(
        "  two processes (detector apart): {:>6.2} s  {:>5.1} frames/s  ({:.2}x the one-process time)",
        two,
        frames / two,
        two / one
    );
    let _ = std::fs::remove_dir_all(&dir);
}
