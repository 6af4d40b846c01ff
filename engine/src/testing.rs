//! Operators that exist to exercise the engine (its tests, benchmarks and smoke runs), named
//! `testing.*`: a test-pattern source, a seeded random scalar, a sum that joins an optional
//! input, simulated work and fault injection. They carry no vision algorithm; `register` adds
//! them to a registry (dynaflow's own registry includes them).

use std::sync::Arc;
use std::time::{Duration, Instant};

use rand_core::Rng;

use crate::msg::{Body, Header, Image, PixelFormat, Scalars};
use crate::op::{Context, In, Inputs, Instance, OpError, OpSpec, Operator, Out, Outputs, Params, Registry, Source};
use crate::{param_enum, params};

/// Add the `testing.*` operators to `r`.
pub fn register(r: &mut Registry) {
    r.register(TEST_PATTERN);
    r.register(SIMULATE_WORK);
    r.register(RANDOM_SCALAR);
    r.register(SCALAR_SUM);
    r.register(FAULT);
}

/// A registry of the `testing.*` operators and the flow operators (`passthrough`, `gate`):
/// engine tests without the operator crates.
pub fn registry() -> Registry {
    let mut r = Registry::new();
    crate::flow::register(&mut r);
    register(&mut r);
    r
}

/// Run `graph` to completion on a two-worker runtime, every recorded message kept in memory
/// (engine and operator tests). Panics if the machine cannot start a tokio runtime.
pub fn run_to_memory(
    graph: &crate::spec::ResolvedGraph,
    options: crate::runtime::RunOptions,
) -> Result<(crate::runtime::RunReport, crate::sink::MemorySink), crate::runtime::RunError> {
    let sink = crate::sink::MemorySink::default();
    let rt =
        tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().expect("a tokio runtime");
    let sinks: Vec<Box<dyn crate::sink::Sink>> = vec![Box::new(sink.clone())];
    let report = rt.block_on(crate::runtime::run(graph, options, sinks))?;
    Ok((report, sink))
}

use crate::flow::{ANY_IN, SAME_OUT, forward};

// --- test_pattern ----------------------------------------------------------------------

params! {
    /// `testing.test_pattern` configuration.
    struct Config {
        /// number of frames
        frames: u64 [1, 100_000_000] = 300,
        /// image width in pixels
        width: u32 [1, 8192] = 64,
        /// image height in pixels
        height: u32 [1, 8192] = 48,
        /// frame rate that sets the stamps (and pacing with --realtime)
        rate_hz: f64 [0.001, 10_000.0] = 30.0,
    }
}

const IMAGE: Out<Image> = Out::new("image", "RGB8 gradient shifted by one pixel per frame");
const TICK: Out<Scalars> = Out::new("tick", "`frame` = sequence number, `time` = stamp in seconds");

const TEST_PATTERN_DOC: &str = "Testing only (engine tests and benchmarks; the `testing.` prefix marks it): A moving RGB gradient and a frame counter at a fixed rate. For engine tests and smoke runs; it is not a camera model and feeds no SLAM result.";

/// `testing.test_pattern`: a moving gradient and a frame counter.
pub const TEST_PATTERN: OpSpec =
    OpSpec::source("testing.test_pattern", "testing", TEST_PATTERN_DOC, build_test_pattern)
        .outputs(&[IMAGE.spec, TICK.spec])
        .params(Config::PARAMS);

fn build_test_pattern(params: &Params) -> Result<Instance, OpError> {
    let config = Config::from_params(params)?;
    Ok(Instance::Source(Box::new(TestPattern { config, frame_id: "camera".into() })))
}

struct TestPattern {
    config: Config,
    frame_id: Arc<str>,
}

impl Source for TestPattern {
    fn next(&mut self, _ctx: &mut Context, seq: u64) -> Result<Option<Outputs>, OpError> {
        if seq >= self.config.frames {
            return Ok(None);
        }
        let (w, h) = (self.config.width, self.config.height);
        let mut img = Image::zeros(w, h, PixelFormat::Rgb8);
        for (i, px) in img.data.chunks_exact_mut(3).enumerate() {
            let x = (i as u64 % u64::from(w) + seq) as u8;
            let y = (i as u64 / u64::from(w)) as u8;
            px.copy_from_slice(&[x, y, x ^ y]);
        }
        let stamp = seq as f64 / self.config.rate_hz;
        let header = Header { seq, stamp, frame_id: self.frame_id.clone() };
        let tick = Scalars { values: vec![("frame".into(), seq as f64), ("time".into(), stamp)] };
        Ok(Some(Outputs::new().send(&IMAGE, header.clone(), img).send(&TICK, header, tick)))
    }

    fn len_hint(&self) -> Option<u64> {
        Some(self.config.frames)
    }
}

// --- simulate_work ---------------------------------------------------------------------

params! {
    struct WorkConfig {
        /// time spent per frame, microseconds
        work_us: u64 [0, 60_000_000] = 1000,
        /// busy-wait instead of sleeping
        spin: bool = false,
    }
}

const SIMULATE_WORK_DOC: &str = "Testing only (engine tests and benchmarks; the `testing.` prefix marks it): Forwards its input after spending `work_us` on the blocking pool (sleeping, or spinning with `spin`). Models a slow consumer.";

/// `testing.simulate_work`: a slow consumer.
pub const SIMULATE_WORK: OpSpec =
    OpSpec::transform("testing.simulate_work", "testing", SIMULATE_WORK_DOC, |p: &Params| {
        Ok(Instance::Transform(Box::new(SimulateWork(WorkConfig::from_params(p)?))))
    })
    .inputs(ANY_IN)
    .outputs(SAME_OUT)
    .params(WorkConfig::PARAMS)
    .cpu_heavy();

struct SimulateWork(WorkConfig);

impl Operator for SimulateWork {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let d = Duration::from_micros(self.0.work_us);
        if self.0.spin {
            let t = Instant::now();
            while t.elapsed() < d {
                std::hint::spin_loop();
            }
        } else {
            std::thread::sleep(d);
        }
        forward(inputs)
    }
}

// --- random_scalar ---------------------------------------------------------------------

param_enum! {
    enum Distribution { Uniform = "uniform", Normal = "normal" }
}

params! {
    struct RandomConfig {
        /// uniform in [0, scale) or normal with σ = scale
        distribution: Distribution = Distribution::Uniform,
        /// range or standard deviation
        scale: f64 [0.0, 1e12] = 1.0,
    }
}

const TRIGGER: In<Body> = In::required("trigger", "any message; one value is drawn per frame");
const VALUE: Out<Scalars> = Out::new("value", "`value`: the draw");

const RANDOM_SCALAR_DOC: &str = "Testing only (engine tests and benchmarks; the `testing.` prefix marks it): Emits one random number per frame from the node's seeded RNG (`value`). Shows that runs with the same seed are identical.";

/// `testing.random_scalar`: one seeded draw per frame.
pub const RANDOM_SCALAR: OpSpec =
    OpSpec::transform("testing.random_scalar", "testing", RANDOM_SCALAR_DOC, |p: &Params| {
        Ok(Instance::Transform(Box::new(RandomScalar(RandomConfig::from_params(p)?))))
    })
    .inputs(&[TRIGGER.spec])
    .outputs(&[VALUE.spec])
    .params(RandomConfig::PARAMS);

struct RandomScalar(RandomConfig);

fn unit(rng: &mut impl Rng) -> f64 {
    // 53 random bits → [0, 1).
    (rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64
}

impl Operator for RandomScalar {
    fn process(&mut self, ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let header = TRIGGER.require(inputs)?.0.header.clone();
        let v = match self.0.distribution {
            Distribution::Normal => {
                // Box–Muller; 1 - u keeps the log argument in (0, 1].
                let (u1, u2) = (1.0 - unit(&mut ctx.rng), unit(&mut ctx.rng));
                (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos() * self.0.scale
            }
            Distribution::Uniform => unit(&mut ctx.rng) * self.0.scale,
        };
        Ok(Outputs::new().send(&VALUE, header, Scalars::one("value", v)))
    }
}

// --- scalar_sum ------------------------------------------------------------------------

const SCALAR_SUM_DOC: &str = "Testing only (engine tests and benchmarks; the `testing.` prefix marks it): Sums the first value of `a` and, when present, of `b` into `sum`; also reports whether `b` was present (`b_present`). Exercises joins and feedback.";

/// `testing.scalar_sum`: a join with an optional input.
pub const SCALAR_SUM: OpSpec = OpSpec::transform("testing.scalar_sum", "testing", SCALAR_SUM_DOC, |_| {
    Ok(Instance::Transform(Box::new(ScalarSum)))
})
.inputs(&[A.spec, B.spec])
.outputs(&[SUM.spec]);

const A: In<Scalars> = In::required("a", "first addend (required)");
const B: In<Scalars> = In::optional("b", "second addend (optional)");
const SUM: Out<Scalars> = Out::new("sum", "`sum`, `b_present`, `b_seq` (frame of `b`, -1 if absent)");

struct ScalarSum;

fn first(s: &Scalars) -> Result<f64, OpError> {
    s.values.first().map(|(_, v)| *v).ok_or_else(|| OpError::Input("empty scalars".into()))
}

impl Operator for ScalarSum {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (a_msg, a) = A.require(inputs)?;
        let b = B.find(inputs)?;
        let sum = first(a)? + b.map(|(_, s)| first(s)).transpose()?.unwrap_or(0.0);
        let values = vec![
            ("sum".into(), sum),
            ("b_present".into(), f64::from(u8::from(b.is_some()))),
            ("b_seq".into(), b.map_or(-1.0, |(m, _)| m.header.seq as f64)),
        ];
        let header = Header { ..a_msg.header.clone() };
        Ok(Outputs::new().send(&SUM, header, Scalars { values }))
    }
}

// --- fault -----------------------------------------------------------------------------

param_enum! {
    enum FaultMode { Error = "error", Panic = "panic" }
}

params! {
    struct FaultConfig {
        /// frame at which to fail
        at_frame: u64 [0, i64::MAX],
        /// return an error or panic
        mode: FaultMode = FaultMode::Error,
    }
}

const FAULT_DOC: &str = "Testing only (engine tests and benchmarks; the `testing.` prefix marks it): Forwards its input until frame `at_frame`, then fails with an error or a panic. Tests shutdown on operator failure.";

/// `testing.fault`: an error or a panic at a given frame.
pub const FAULT: OpSpec = OpSpec::transform("testing.fault", "testing", FAULT_DOC, |p: &Params| {
    Ok(Instance::Transform(Box::new(Fault(FaultConfig::from_params(p)?))))
})
.inputs(ANY_IN)
.outputs(SAME_OUT)
.params(FaultConfig::PARAMS);

struct Fault(FaultConfig);

impl Operator for Fault {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        if inputs.seq >= self.0.at_frame {
            if self.0.mode == FaultMode::Panic {
                #[allow(clippy::panic)]
                {
                    panic!("fault injected at frame {}", inputs.seq);
                }
            }
            return Err(OpError::Failed(format!("fault injected at frame {}", inputs.seq)));
        }
        forward(inputs)
    }
}
