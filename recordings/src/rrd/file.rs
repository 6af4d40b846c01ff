//! The `.rrd` file writer, and the footer manifest it keeps while the run lasts.
//!
//! An `.rrd` file ends with a footer: a manifest with a row per chunk (where it lies in the
//! file, its entity, and per timeline and component the time range and row count it covers),
//! which lets a viewer index a file without reading it. The SDK's encoder builds it in one
//! dense table, a column per component of *any* entity (each temporal component also gets a
//! static column), so every chunk costs a row as wide as the whole recording: about 2 KB on the
//! default graph's 40-odd components, held until the file closes, which made a long run's memory
//! grow with its length (docs/benchmarks.md, fourth pass). Here the same manifest is kept as
//! one SDK builder per entity, whose rows only carry that entity's few components, and merged
//! into the dense table once, when the file is finished (the SDK's `RawRrdManifest::merge`,
//! which pads what an entity lacks exactly as the single builder pads it), rows back in file
//! order. The footer is the one the SDK would have written: a unit test writes the same
//! messages both ways and compares the manifests and the bytes before them.

use std::collections::HashMap;
use std::fs::File;
use std::io::BufWriter;

use rerun::external::arrow;
use rerun::external::re_log_encoding::{
    CrateVersion, Encoder, EncodingOptions, RawRrdManifest, RrdFooter, RrdManifestBuilder, ToTransport as _,
};
use rerun::external::re_log_types::{EntityPath, LogMsg, StoreId};

/// Compressed chunks (LZ4), as the SDK's `FileSink` writes.
const OPTIONS: EncodingOptions = EncodingOptions::PROTOBUF_COMPRESSED;

type RrdEncoder = Encoder<BufWriter<File>>;

/// The `.rrd` file writer: each chunk the batcher hands over is encoded (Arrow IPC, LZ4,
/// protobuf framing) and written on the SDK's forwarding thread, there and then. The SDK's own
/// `FileSink` queues up to 1024 messages for a writer thread of its own, whatever their size
/// (image chunks are megabytes), so what waits between the batcher and the disk varied with how
/// far the writer lagged; here nothing waits: a slow disk blocks the forwarding thread, which
/// fills the batcher's bounded channel, which blocks the recorder, and the engine's recorder
/// queue stands between it and the graph. The first write error (a full disk) is kept, stops
/// the writing, and fails the recorder with the file's name.
pub(super) struct RrdFile {
    pub(super) state: std::sync::Arc<SharedFile>,
}

/// The encoder and the footer being built.
struct Writer {
    encoder: RrdEncoder,
    footer: Footer,
}

/// The writer, shared by the sink the SDK drives and the recorder that finishes the file.
pub(super) struct SharedFile {
    /// `None` once the file is finished.
    writer: std::sync::Mutex<Option<Writer>>,
    /// The first write error, readable without waiting for a chunk being encoded.
    failed: std::sync::OnceLock<String>,
}

impl SharedFile {
    pub(super) fn create(path: &std::path::Path) -> Result<Self, String> {
        let file = dynaflow_engine::files::create_new(path).map_err(|e| e.to_string())?;
        let mut encoder = Encoder::new_eager(CrateVersion::LOCAL, OPTIONS, BufWriter::with_capacity(1 << 20, file))
            .map_err(|e| e.to_string())?;
        // The manifest is kept here (see the module doc), not by the encoder.
        encoder.do_not_emit_footer();
        // The stream header reaches the file now, so a file that cannot be written (a full
        // disk) fails the run before it starts, as the other recorders do.
        if let Err(e) = encoder.flush_blocking() {
            // Unwrapped, the encoder does not try (and warn about) its end-of-stream on drop.
            let _ = encoder.into_inner();
            return Err(e.to_string());
        }
        let writer = Writer { encoder, footer: Footer::default() };
        Ok(Self { writer: std::sync::Mutex::new(Some(writer)), failed: std::sync::OnceLock::new() })
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Option<Writer>> {
        // A panic while encoding leaves nothing half-mutated that matters here: keep writing.
        self.writer.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// Runs `f` on the writer unless an earlier write failed or the file is finished; keeps
    /// the first error, after which nothing more is written.
    fn write(&self, f: impl FnOnce(&mut Writer) -> Result<(), String>) -> Result<(), String> {
        let mut writer = self.lock();
        if let Some(e) = self.failed() {
            return Err(e.to_owned());
        }
        let Some(writer) = writer.as_mut() else { return Err("the file is already finished".into()) };
        f(writer).inspect_err(|e| {
            let _ = self.failed.set(e.clone());
        })
    }

    /// Encodes and writes `msg`, and adds its chunk to the footer.
    fn append(&self, msg: &LogMsg) -> Result<(), String> {
        self.write(|w| w.append(msg))
    }

    /// Writes the footer and the end-of-stream marker, flushes, and closes the file.
    pub(super) fn finish(&self) -> Result<(), String> {
        self.write(Writer::finish)?;
        *self.lock() = None;
        Ok(())
    }

    pub(super) fn failed(&self) -> Option<&str> {
        self.failed.get().map(String::as_str)
    }
}

impl Writer {
    fn append(&mut self, msg: &LogMsg) -> Result<(), String> {
        let transport = msg.to_transport(OPTIONS.compression).map_err(|e| e.to_string())?;
        // SAFETY: the message was encoded with the compression the encoder was created with,
        // which is all `append_transport_without_footer` asks of it.
        #[allow(unsafe_code)]
        let (span, uncompressed) =
            unsafe { self.encoder.append_transport_without_footer(&transport) }.map_err(|e| e.to_string())?;
        if let LogMsg::ArrowMsg(store, chunk) = msg {
            self.footer.append(store, &chunk.batch, span, uncompressed)?;
        }
        Ok(())
    }

    fn finish(&mut self) -> Result<(), String> {
        let footer = std::mem::take(&mut self.footer).build()?;
        // SAFETY: the footer indexes exactly the chunks this encoder wrote, at the offsets it
        // returned; `rerun rrd verify` (CI) reads every chunk through it, and a unit test
        // compares it with the footer the SDK's own encoder writes for the same messages.
        #[allow(unsafe_code)]
        unsafe { self.encoder.finish_with_custom_footer(&footer) }.map_err(|e| e.to_string())?;
        self.encoder.flush_blocking().map_err(|e| e.to_string())
    }
}

impl Drop for SharedFile {
    /// A recording dropped without `close` (an error elsewhere ended the run) still gets its
    /// footer, as the SDK's file sink does.
    fn drop(&mut self) {
        // Does nothing once finished or after a write error.
        let _ = self.finish();
        // After a write error the file is given up (the error was reported); unwrapped, the
        // encoder does not try its end-of-stream again on drop.
        if let Some(writer) = self.lock().take() {
            let _ = writer.encoder.into_inner();
        }
    }
}

impl rerun::sink::LogSink for RrdFile {
    fn send(&self, msg: LogMsg) {
        // An error is kept and reported by the recorder.
        let _ = self.state.append(&msg);
    }

    fn flush_blocking(&self, _timeout: std::time::Duration) -> Result<(), rerun::sink::SinkFlushError> {
        self.state
            .write(|w| w.encoder.flush_blocking().map_err(|e| e.to_string()))
            .map_err(rerun::sink::SinkFlushError::failed)
    }

    fn defers_finalization_to_shutdown(&self) -> bool {
        true
    }
}

/// The footer's manifest while the file is written: per recording, one SDK builder per entity.
#[derive(Default)]
struct Footer {
    builders: HashMap<StoreId, HashMap<EntityPath, RrdManifestBuilder>>,
}

impl Footer {
    fn append(
        &mut self,
        store: &StoreId,
        batch: &arrow::array::RecordBatch,
        span: re_span::Span<u64>,
        uncompressed: u64,
    ) -> Result<(), String> {
        let chunk = re_sorbet::ChunkBatch::try_from(batch).map_err(|e| e.to_string())?;
        let entities = self.builders.entry(store.clone()).or_default();
        let builder = entities.entry(chunk.entity_path().clone()).or_default();
        builder.append(&chunk, span, uncompressed).map_err(|e| e.to_string())
    }

    /// The footer: per recording, the entities' manifests merged into one, rows in file order.
    fn build(self) -> Result<RrdFooter, String> {
        let mut manifests = HashMap::new();
        for (store, entities) in self.builders {
            // In path order, so the merged columns come in the same order every run.
            let mut entities: Vec<_> = entities.into_iter().collect();
            entities.sort_by(|a, b| a.0.cmp(&b.0));
            let parts = entities
                .into_iter()
                .map(|(_, builder)| builder.build(store.clone()))
                .collect::<Result<Vec<_>, _>>()
                .map_err(|e| e.to_string())?;
            let mut manifest = RawRrdManifest::merge(store.clone(), parts).map_err(|e| e.to_string())?;
            manifest.data = in_file_order(&manifest)?;
            manifests.insert(store, manifest);
        }
        Ok(RrdFooter { manifests })
    }
}

/// The manifest's rows sorted by the chunks' byte offsets (the order the SDK's builder has).
fn in_file_order(manifest: &RawRrdManifest) -> Result<arrow::array::RecordBatch, String> {
    let offsets = manifest.col_chunk_byte_offset_raw().map_err(|e| e.to_string())?;
    let order = arrow::compute::sort_to_indices(offsets, None, None).map_err(|e| e.to_string())?;
    arrow::compute::take_record_batch(&manifest.data, &order).map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use rerun::external::re_log_encoding::{CrateVersion, Encoder, RawRrdManifest, RrdManifest};
    use rerun::external::re_log_types::LogMsg;

    /// Messages of a small recording: several entities, static and temporal data, two
    /// timelines, components that come and go, chunks cut at every flush.
    fn messages() -> Vec<LogMsg> {
        let (rec, storage) = rerun::RecordingStreamBuilder::new("footer-test").memory().expect("memory recording");
        rec.log_static("cam", &rerun::Pinhole::from_focal_length_and_resolution([500.0, 500.0], [640.0, 480.0]))
            .expect("log");
        for frame in 0..30i64 {
            rec.set_time_sequence("frame", frame);
            if frame % 3 == 0 {
                rec.set_duration_secs("sensor", frame as f64 / 30.0);
            }
            let x = frame as f32;
            rec.log("cam/points", &rerun::Points2D::new([(x, 1.0), (2.0, x)]).with_radii([1.0])).expect("log");
            if frame % 2 == 0 {
                rec.log("cam/boxes", &rerun::Boxes2D::from_mins_and_sizes([(0.0, 0.0)], [(x, x)]).with_labels(["a"]))
                    .expect("log");
            }
            rec.log("metrics/err", &rerun::Scalars::single(f64::from(x) * 0.5)).expect("log");
            if frame % 10 == 9 {
                rec.log_static("cam/classes", &rerun::TextDocument::new(format!("cut {frame}"))).expect("log");
                rec.flush_blocking().expect("flush");
            }
        }
        rec.flush_blocking().expect("flush");
        storage.take()
    }

    #[test]
    fn the_footer_is_the_one_the_sdk_encoder_writes() {
        let msgs = messages();
        let dir = std::env::temp_dir().join(format!("dynaflow-rrd-footer-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");

        // The SDK's encoder, with its own footer.
        let sdk = dir.join("sdk.rrd");
        let mut encoder = Encoder::new_eager(
            CrateVersion::LOCAL,
            super::OPTIONS,
            std::io::BufWriter::new(std::fs::File::create(&sdk).expect("create")),
        )
        .expect("encoder");
        for m in &msgs {
            encoder.append(m).expect("append");
        }
        encoder.finish().expect("finish");
        drop(encoder.into_inner().expect("inner"));

        // Ours.
        let ours = dir.join("ours.rrd");
        let file = super::SharedFile::create(&ours).expect("create");
        for m in &msgs {
            file.append(m).expect("append");
        }
        file.finish().expect("finish");
        drop(file);

        let (a, b) = (std::fs::read(&sdk).expect("read"), std::fs::read(&ours).expect("read"));
        std::fs::remove_dir_all(&dir).ok();
        let raw = |bytes: &[u8]| {
            let mut m = RawRrdManifest::from_rrd_bytes(bytes).expect("footer");
            assert_eq!(m.len(), 1, "one recording");
            m.remove(0)
        };
        let (raw_a, raw_b) = (raw(&a), raw(&b));
        raw_b.sanity_check_heavy().expect("our manifest passes the SDK's checks");
        let (ma, mb) = (RrdManifest::try_new(&raw_a).expect("sdk"), RrdManifest::try_new(&raw_b).expect("ours"));
        assert!(ma.num_chunks() > 10, "the test recording has chunks to index: {}", ma.num_chunks());
        assert_eq!(ma.store_id(), mb.store_id());
        assert_eq!(ma.col_chunk_ids(), mb.col_chunk_ids());
        assert!(ma.col_chunk_entity_path().eq(mb.col_chunk_entity_path()));
        assert!(ma.col_chunk_is_static().eq(mb.col_chunk_is_static()));
        assert_eq!(ma.col_chunk_num_rows(), mb.col_chunk_num_rows());
        assert_eq!(ma.col_chunk_byte_offset(), mb.col_chunk_byte_offset());
        assert_eq!(ma.col_chunk_byte_size(), mb.col_chunk_byte_size());
        assert_eq!(ma.col_chunk_byte_size_uncompressed(), mb.col_chunk_byte_size_uncompressed());
        assert_eq!(ma.static_map(), mb.static_map());
        assert_eq!(ma.temporal_map(), mb.temporal_map());
        // The same columns (the merged ones in another order), with the same values.
        let columns = |m: &RawRrdManifest| {
            let schema = m.data.schema();
            let mut c: Vec<_> =
                schema.fields().iter().zip(m.data.columns()).map(|(f, c)| (f.name().clone(), c.to_data())).collect();
            c.sort_by(|x, y| x.0.cmp(&y.0));
            c
        };
        let (ca, cb) = (columns(&raw_a), columns(&raw_b));
        assert_eq!(ca.iter().map(|c| &c.0).collect::<Vec<_>>(), cb.iter().map(|c| &c.0).collect::<Vec<_>>());
        for ((name, x), (_, y)) in ca.iter().zip(&cb) {
            assert_eq!(x, y, "column {name}");
        }
        let mut fields_a: Vec<_> = raw_a.sorbet_schema.fields().iter().map(|f| f.name().clone()).collect();
        let mut fields_b: Vec<_> = raw_b.sorbet_schema.fields().iter().map(|f| f.name().clone()).collect();
        fields_a.sort();
        fields_b.sort();
        assert_eq!(fields_a, fields_b, "the recording's schema");
        // Everything before the footer (the header and every chunk) is byte for byte the same.
        let end = ma.col_chunk_byte_offset().iter().zip(ma.col_chunk_byte_size()).map(|(o, s)| o + s).max();
        let end = usize::try_from(end.expect("chunks")).expect("size");
        assert_eq!(a[..end], b[..end]);
    }
}
