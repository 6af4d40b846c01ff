//! The one source skeleton: every reader (TUM RGB-D, KITTI, image folders) and the generator
//! is a [`Sequence`] of frames by index; reading frame `seq`, stamping its messages,
//! `on_error`, counting what was skipped and the sequence's length are [`SequenceSource`]'s,
//! and each operator says only how one frame becomes messages (its `emit` function).

use std::sync::Arc;

use dynaflow_datasets::Sequence;
use dynaflow_engine::msg::{Header, Pose};
use dynaflow_engine::op::{Context, OpError, Out, Outputs, Source};
use dynaflow_engine::param_enum;

use crate::report::{BagReport, NodeReport, SourceReport};

param_enum! {
    /// What an unreadable frame does.
    pub enum OnError { Fail = "fail", Skip = "skip" }
}

/// How one frame of `S` becomes messages; `header` is the camera's (the frame's `seq` and
/// stamp).
pub(crate) type Emit<S> = fn(&S, <S as Sequence>::Frame, &Header) -> Outputs;

/// Sends `world_from_cam` on a ground-truth pose port, stamped as `header` in the `world` frame.
pub(crate) fn ground_truth_pose(out: &mut Outputs, port: &Out<Pose>, header: &Header, world_from_cam: Pose) {
    port.push(out, Header { frame_id: "world".into(), ..header.clone() }, world_from_cam);
}

/// A source over a [`Sequence`]: frame `seq` at `seq`, the end where the sequence ends.
pub(crate) struct SequenceSource<S: Sequence> {
    sequence: S,
    emit: Emit<S>,
    /// Where the frames come from (the skip warning names it).
    origin: String,
    on_error: OnError,
    skipped: u64,
    frame_id: Arc<str>,
    /// What a bag's pairing left out, for the node's report.
    bag_report: Option<fn(&S) -> BagReport>,
}

impl<S: Sequence> SequenceSource<S> {
    /// Streams `sequence` (read from `origin`) in the `camera` frame.
    pub(crate) fn new(sequence: S, emit: Emit<S>, origin: &std::path::Path, on_error: OnError) -> Self {
        let origin = origin.display().to_string();
        Self { sequence, emit, origin, on_error, skipped: 0, frame_id: "camera".into(), bag_report: None }
    }

    /// Adds what `report` says of the sequence (a bag's topics and left-out messages) to the
    /// node's report.
    pub(crate) fn with_bag_report(mut self, report: fn(&S) -> BagReport) -> Self {
        self.bag_report = Some(report);
        self
    }
}

impl<S: Sequence> Source for SequenceSource<S> {
    fn start(&mut self, ctx: &mut Context) -> Result<(), OpError> {
        self.sequence.seed(ctx.seed);
        Ok(())
    }

    fn next(&mut self, _ctx: &mut Context, seq: u64) -> Result<Option<Outputs>, OpError> {
        match self.sequence.read(seq as usize) {
            Ok(None) => Ok(None),
            Ok(Some(f)) => {
                let header = Header { seq, stamp: S::stamp(&f), frame_id: self.frame_id.clone() };
                Ok(Some((self.emit)(&self.sequence, f, &header)))
            }
            Err(e) if self.on_error == OnError::Skip => {
                tracing::warn!("skipping frame {seq}: {e}");
                self.skipped += 1;
                Ok(Some(Outputs::new()))
            }
            Err(e) => Err(OpError::library(e)),
        }
    }

    fn stop(&mut self, ctx: &mut Context) -> Result<(), OpError> {
        if self.skipped > 0 {
            tracing::warn!("{}: skipped {} of {} frames", self.origin, self.skipped, self.sequence.len());
        }
        let bag = self.bag_report.map(|f| f(&self.sequence));
        if self.skipped > 0 || bag.is_some() {
            ctx.report = Some(NodeReport::from(SourceReport { frames_skipped: self.skipped, bag }).to_json());
        }
        Ok(())
    }

    fn len_hint(&self) -> Option<u64> {
        Some(self.sequence.len() as u64)
    }
}
