//! Per-frame utility operators.

use std::time::{Duration, Instant};

use dynaflow_engine::msg::{Body, Header, Scalars, SegmentationMask};
use dynaflow_engine::op::{
    Context, In, InputRole, Inputs, Instance, OpError, OpKind, OpSpec, Operator, Out, Outputs, Params, PortSpec,
};
use dynaflow_engine::{param_enum, params};
use rand_core::Rng;
use std::collections::BTreeSet;

const INPUT: In<Body> = In::required("input", "any message");
const OUTPUT: Out<Body> = Out::like("output", "input", "the input message, unchanged");
const ANY_IN: &[PortSpec] = &[INPUT.spec];
const SAME_OUT: &[PortSpec] = &[OUTPUT.spec];

fn forward(inputs: &Inputs) -> Result<Outputs, OpError> {
    let (msg, body) = INPUT.require(inputs)?;
    Ok(Outputs::new().send(&OUTPUT, msg.header.clone(), body.clone()))
}

// --- passthrough -----------------------------------------------------------------------

pub(super) const PASSTHROUGH: OpSpec = OpSpec {
    name: "passthrough",
    family: "util",
    doc: "Forwards its input unchanged. Used to measure engine overhead per hop.",
    kind: OpKind::Transform,
    inputs: ANY_IN,
    outputs: SAME_OUT,
    params: &[],
    cpu_heavy: false,
    ground_truth_outputs: None,
    build: |_| Ok(Instance::Transform(Box::new(Passthrough))),
};

struct Passthrough;

impl Operator for Passthrough {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        forward(inputs)
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

pub(super) const SIMULATE_WORK: OpSpec = OpSpec {
    name: "testing.simulate_work",
    family: "testing",
    doc: "Testing only (engine tests and benchmarks; the `testing.` prefix marks it): Forwards its input after spending `work_us` on the blocking pool (sleeping, or spinning with `spin`). Models a slow consumer.",
    kind: OpKind::Transform,
    inputs: ANY_IN,
    outputs: SAME_OUT,
    params: WorkConfig::PARAMS,
    cpu_heavy: true,
    ground_truth_outputs: None,
    build: |p: &Params| Ok(Instance::Transform(Box::new(SimulateWork(WorkConfig::from_params(p)?)))),
};

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

pub(super) const RANDOM_SCALAR: OpSpec = OpSpec {
    name: "testing.random_scalar",
    family: "testing",
    doc: "Testing only (engine tests and benchmarks; the `testing.` prefix marks it): Emits one random number per frame from the node's seeded RNG (`value`). Shows that runs with the same seed are identical.",
    kind: OpKind::Transform,
    inputs: &[TRIGGER.spec],
    outputs: &[VALUE.spec],
    params: RandomConfig::PARAMS,
    cpu_heavy: false,
    ground_truth_outputs: None,
    build: |p: &Params| Ok(Instance::Transform(Box::new(RandomScalar(RandomConfig::from_params(p)?)))),
};

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

// --- gate ------------------------------------------------------------------------------

params! {
    struct GateConfig {
        /// period in frames
        every: u64 [1, 1_000_000] = 5,
        /// phase in frames
        offset: u64 [0, 1_000_000] = 0,
    }
}

pub(super) const GATE: OpSpec = OpSpec {
    name: "gate",
    family: "util",
    doc: "Forwards frames whose number `k` satisfies `k % every == offset`; other frames carry nothing (a watermark). Models a key-frame gate.",
    kind: OpKind::Transform,
    inputs: ANY_IN,
    outputs: SAME_OUT,
    params: GateConfig::PARAMS,
    cpu_heavy: false,
    ground_truth_outputs: None,
    build: |p: &Params| Ok(Instance::Transform(Box::new(Gate(GateConfig::from_params(p)?)))),
};

struct Gate(GateConfig);

impl Operator for Gate {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        if inputs.seq % self.0.every == self.0.offset % self.0.every { forward(inputs) } else { Ok(Outputs::new()) }
    }
}

// --- scalar_sum ------------------------------------------------------------------------

pub(super) const SCALAR_SUM: OpSpec = OpSpec {
    name: "testing.scalar_sum",
    family: "testing",
    doc: "Testing only (engine tests and benchmarks; the `testing.` prefix marks it): Sums the first value of `a` and, when present, of `b` into `sum`; also reports whether `b` was present (`b_present`). Exercises joins and feedback.",
    kind: OpKind::Transform,
    inputs: &[A.spec, B.spec],
    outputs: &[SUM.spec],
    params: &[],
    cpu_heavy: false,
    ground_truth_outputs: None,
    build: |_| Ok(Instance::Transform(Box::new(ScalarSum))),
};

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
        let b_msg = B.message(inputs)?;
        let b = B.get(inputs)?;
        let sum = first(a)? + b.map(first).transpose()?.unwrap_or(0.0);
        let values = vec![
            ("sum".into(), sum),
            ("b_present".into(), f64::from(u8::from(b.is_some()))),
            ("b_seq".into(), b_msg.map_or(-1.0, |m| m.header.seq as f64)),
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

pub(super) const FAULT: OpSpec = OpSpec {
    name: "testing.fault",
    family: "testing",
    doc: "Testing only (engine tests and benchmarks; the `testing.` prefix marks it): Forwards its input until frame `at_frame`, then fails with an error or a panic. Tests shutdown on operator failure.",
    kind: OpKind::Transform,
    inputs: ANY_IN,
    outputs: SAME_OUT,
    params: FaultConfig::PARAMS,
    cpu_heavy: false,
    ground_truth_outputs: None,
    build: |p: &Params| Ok(Instance::Transform(Box::new(Fault(FaultConfig::from_params(p)?)))),
};

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

// --- mask_stats ------------------------------------------------------------------------

pub(super) const MASK_STATS: OpSpec = OpSpec {
    name: "mask_stats",
    family: "util",
    doc: "Statistics of a segmentation mask: the fraction of pixels of a non-background class (`dynamic_fraction`) and the number of distinct instances (`instances`). Shows how dynamic each frame of a sequence is.",
    kind: OpKind::Transform,
    inputs: &[MASK.spec],
    outputs: &[STATS.spec],
    params: &[],
    cpu_heavy: false,
    ground_truth_outputs: None,
    build: |_| Ok(Instance::Transform(Box::new(MaskStats))),
};

const MASK: In<SegmentationMask> =
    In::required("mask", "class (and instance) mask; class 0 is background/static").with_role(InputRole::Statistics);
const STATS: Out<Scalars> = Out::new("stats", "`dynamic_fraction`, `instances`");

struct MaskStats;

impl Operator for MaskStats {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, m) = MASK.require(inputs)?;
        let dynamic = m.classes.iter().filter(|&&c| c != 0).count();
        let fraction = if m.classes.is_empty() { 0.0 } else { dynamic as f64 / m.classes.len() as f64 };
        let instances =
            m.instances.as_ref().map_or(0, |i| i.iter().filter(|&&v| v != 0).collect::<BTreeSet<_>>().len());
        let values = vec![("dynamic_fraction".into(), fraction), ("instances".into(), instances as f64)];
        Ok(Outputs::new().send(&STATS, msg.header.clone(), Scalars { values }))
    }
}
