//! Per-frame utility operators.

use std::time::{Duration, Instant};

use dynaflow_engine::msg::{Body, Header, PortType, Scalars};
use dynaflow_engine::op::{
    Context, Default, InputRole, Inputs, Instance, OpError, OpKind, OpSpec, Operator, Outputs, ParamSpec, ParamType,
    Params, PortSpec,
};
use rand_core::Rng;
use std::collections::BTreeSet;

const ANY_IN: &[PortSpec] = &[PortSpec::input("input", PortType::Any, "any message")];
const SAME_OUT: &[PortSpec] = &[PortSpec::output_like("output", "input", "the input message, unchanged")];

fn forward(inputs: &Inputs) -> Result<Outputs, OpError> {
    let msg = inputs.require("input")?;
    let mut out = Outputs::new();
    out.push("output", msg.header.clone(), msg.body.clone());
    Ok(out)
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

#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct WorkConfig {
    work_us: u64,
    spin: bool,
}

pub(super) const SIMULATE_WORK: OpSpec = OpSpec {
    name: "testing.simulate_work",
    family: "testing",
    doc: "Testing only (engine tests and benchmarks; the `testing.` prefix marks it): Forwards its input after spending `work_us` on the blocking pool (sleeping, or spinning with `spin`). Models a slow consumer.",
    kind: OpKind::Transform,
    inputs: ANY_IN,
    outputs: SAME_OUT,
    params: &[
        ParamSpec {
            name: "work_us",
            ty: ParamType::Int { min: 0, max: 60_000_000 },
            default: Default::Int(1000),
            doc: "time spent per frame, microseconds",
        },
        ParamSpec {
            name: "spin",
            ty: ParamType::Bool,
            default: Default::Bool(false),
            doc: "busy-wait instead of sleeping",
        },
    ],
    cpu_heavy: true,
    ground_truth_outputs: None,
    build: |p: &Params| Ok(Instance::Transform(Box::new(SimulateWork(p.parse()?)))),
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

#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct RandomConfig {
    distribution: String,
    scale: f64,
}

pub(super) const RANDOM_SCALAR: OpSpec = OpSpec {
    name: "testing.random_scalar",
    family: "testing",
    doc: "Testing only (engine tests and benchmarks; the `testing.` prefix marks it): Emits one random number per frame from the node's seeded RNG (`value`). Shows that runs with the same seed are identical.",
    kind: OpKind::Transform,
    inputs: &[PortSpec::input("trigger", PortType::Any, "any message; one value is drawn per frame")],
    outputs: &[PortSpec::output("value", PortType::Scalars, "`value`: the draw")],
    params: &[
        ParamSpec {
            name: "distribution",
            ty: ParamType::Enum { values: &["uniform", "normal"] },
            default: Default::Str("uniform"),
            doc: "uniform in [0, scale) or normal with σ = scale",
        },
        ParamSpec {
            name: "scale",
            ty: ParamType::Float { min: 0.0, max: 1e12 },
            default: Default::Float(1.0),
            doc: "range or standard deviation",
        },
    ],
    cpu_heavy: false,
    ground_truth_outputs: None,
    build: |p: &Params| Ok(Instance::Transform(Box::new(RandomScalar(p.parse()?)))),
};

struct RandomScalar(RandomConfig);

fn unit(rng: &mut impl Rng) -> f64 {
    // 53 random bits → [0, 1).
    (rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64
}

impl Operator for RandomScalar {
    fn process(&mut self, ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let header = inputs.require("trigger")?.header.clone();
        let v = if self.0.distribution == "normal" {
            // Box–Muller; 1 - u keeps the log argument in (0, 1].
            let (u1, u2) = (1.0 - unit(&mut ctx.rng), unit(&mut ctx.rng));
            (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos() * self.0.scale
        } else {
            unit(&mut ctx.rng) * self.0.scale
        };
        Ok(Outputs::new().with("value", header, Body::Scalars(Scalars::one("value", v))))
    }
}

// --- gate ------------------------------------------------------------------------------

#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct GateConfig {
    every: u64,
    offset: u64,
}

pub(super) const GATE: OpSpec = OpSpec {
    name: "gate",
    family: "util",
    doc: "Forwards frames whose number `k` satisfies `k % every == offset`; other frames carry nothing (a watermark). Models a key-frame gate.",
    kind: OpKind::Transform,
    inputs: ANY_IN,
    outputs: SAME_OUT,
    params: &[
        ParamSpec {
            name: "every",
            ty: ParamType::Int { min: 1, max: 1_000_000 },
            default: Default::Int(5),
            doc: "period in frames",
        },
        ParamSpec {
            name: "offset",
            ty: ParamType::Int { min: 0, max: 1_000_000 },
            default: Default::Int(0),
            doc: "phase in frames",
        },
    ],
    cpu_heavy: false,
    ground_truth_outputs: None,
    build: |p: &Params| Ok(Instance::Transform(Box::new(Gate(p.parse()?)))),
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
    inputs: &[
        PortSpec::input("a", PortType::Scalars, "first addend (required)"),
        PortSpec::optional("b", PortType::Scalars, "second addend (optional)"),
    ],
    outputs: &[PortSpec::output("sum", PortType::Scalars, "`sum`, `b_present`, `b_seq` (frame of `b`, -1 if absent)")],
    params: &[],
    cpu_heavy: false,
    ground_truth_outputs: None,
    build: |_| Ok(Instance::Transform(Box::new(ScalarSum))),
};

struct ScalarSum;

fn first(body: &Body) -> Result<f64, OpError> {
    match body {
        Body::Scalars(s) => s.values.first().map(|(_, v)| *v).ok_or_else(|| OpError::Input("empty scalars".into())),
        other => Err(OpError::Input(format!("expected scalars, got {}", other.port_type()))),
    }
}

impl Operator for ScalarSum {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let a = inputs.require("a")?;
        let b = inputs.get("b");
        let sum = first(&a.body)? + b.map(|m| first(&m.body)).transpose()?.unwrap_or(0.0);
        let values = vec![
            ("sum".into(), sum),
            ("b_present".into(), f64::from(u8::from(b.is_some()))),
            ("b_seq".into(), b.map_or(-1.0, |m| m.header.seq as f64)),
        ];
        let header = Header { ..a.header.clone() };
        Ok(Outputs::new().with("sum", header, Body::Scalars(Scalars { values })))
    }
}

// --- fault -----------------------------------------------------------------------------

#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct FaultConfig {
    at_frame: u64,
    mode: String,
}

pub(super) const FAULT: OpSpec = OpSpec {
    name: "testing.fault",
    family: "testing",
    doc: "Testing only (engine tests and benchmarks; the `testing.` prefix marks it): Forwards its input until frame `at_frame`, then fails with an error or a panic. Tests shutdown on operator failure.",
    kind: OpKind::Transform,
    inputs: ANY_IN,
    outputs: SAME_OUT,
    params: &[
        ParamSpec {
            name: "at_frame",
            ty: ParamType::Int { min: 0, max: i64::MAX },
            default: Default::Required,
            doc: "frame at which to fail",
        },
        ParamSpec {
            name: "mode",
            ty: ParamType::Enum { values: &["error", "panic"] },
            default: Default::Str("error"),
            doc: "return an error or panic",
        },
    ],
    cpu_heavy: false,
    ground_truth_outputs: None,
    build: |p: &Params| Ok(Instance::Transform(Box::new(Fault(p.parse()?)))),
};

struct Fault(FaultConfig);

impl Operator for Fault {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        if inputs.seq >= self.0.at_frame {
            if self.0.mode == "panic" {
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
    inputs: &[PortSpec::input("mask", PortType::Mask, "class (and instance) mask; class 0 is background/static")
        .with_role(InputRole::Statistics)],
    outputs: &[PortSpec::output("stats", PortType::Scalars, "`dynamic_fraction`, `instances`")],
    params: &[],
    cpu_heavy: false,
    ground_truth_outputs: None,
    build: |_| Ok(Instance::Transform(Box::new(MaskStats))),
};

struct MaskStats;

impl Operator for MaskStats {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let msg = inputs.require("mask")?;
        let Body::Mask(m) = &msg.body else {
            return Err(OpError::Input(format!("expected a mask, got {}", msg.body.port_type())));
        };
        let dynamic = m.classes.iter().filter(|&&c| c != 0).count();
        let fraction = if m.classes.is_empty() { 0.0 } else { dynamic as f64 / m.classes.len() as f64 };
        let instances =
            m.instances.as_ref().map_or(0, |i| i.iter().filter(|&&v| v != 0).collect::<BTreeSet<_>>().len());
        let values = vec![("dynamic_fraction".into(), fraction), ("instances".into(), instances as f64)];
        Ok(Outputs::new().with("stats", msg.header.clone(), Body::Scalars(Scalars { values })))
    }
}
