//! `dynaflow merge`: the recordings of one run split over machines, each machine's
//! own nodes, joined into one `.rrd` or one MCAP file of the whole run.
//!
//! - MCAP: every input's messages interleaved by log time (the frames' sensor time stamps:
//!   one clock for every machine, the dataset's), each channel's metadata gaining `machine`,
//!   each input's `dynaflow` metadata kept as `dynaflow.<machine>`, and a `dynaflow` record
//!   of the first input with `machines` (`name=file` pairs) added.
//! - `.rrd`: the first input's recording store; the other inputs' chunks moved into it
//!   (their own store info and blueprints left out). Entity paths (`/<node>/<port>`) do not
//!   collide: each node runs on one machine.
//!
//! Inputs are refused, naming the file, unless they come from one run of one graph (the same
//! graph digest in MCAP, the same application id in `.rrd`) and from different machines.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// One input: the machine that wrote it and the file.
#[derive(Clone, Debug)]
pub struct Input {
    /// Machine name.
    pub machine: String,
    /// The recording.
    pub path: PathBuf,
}

impl Input {
    /// The machine from a file named `<stem>.<machine>.<ext>` (as `dynaflow run --machine`
    /// names it), else the file's stem.
    pub fn from_path(path: &Path) -> Self {
        let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        let machine = stem.rsplit_once('.').map_or(stem.as_str(), |(_, m)| m).to_owned();
        Self { machine, path: path.to_path_buf() }
    }
}

fn check_machines(inputs: &[Input], out: &Path) -> Result<(), String> {
    use dynaflow_engine::files::{refuse_overwriting_inputs, same_file};
    if inputs.len() < 2 {
        return Err("give the recordings of at least two machines".into());
    }
    refuse_overwriting_inputs("--out", out, inputs.iter().map(|i| i.path.as_path()))?;
    for (i, a) in inputs.iter().enumerate() {
        // Machine names are graph ids (they become `dynaflow.<machine>` records and channel
        // metadata): no `/`, `,`, `..` or empty names.
        if !dynaflow_engine::spec::valid_id(&a.machine) {
            return Err(format!(
                "{}: machine name `{}` is not a machine id (a letter or `_`, then letters, digits, `_` and `-`)",
                a.path.display(),
                a.machine
            ));
        }
        if let Some(b) = inputs[..i].iter().find(|b| same_file(&b.path, &a.path)) {
            return Err(format!(
                "{} and {} are the same file: give one recording per machine",
                b.path.display(),
                a.path.display()
            ));
        }
        if let Some(b) = inputs[..i].iter().find(|b| b.machine == a.machine) {
            return Err(format!(
                "{} and {} are both from machine `{}`: give one recording per machine",
                b.path.display(),
                a.path.display(),
                a.machine
            ));
        }
    }
    Ok(())
}

/// Merge MCAP recordings into `out`; returns the number of messages written.
pub fn merge_mcap(inputs: &[Input], out: &Path) -> Result<u64, String> {
    check_machines(inputs, out)?;
    let bufs: Vec<Vec<u8>> = inputs
        .iter()
        .map(|i| std::fs::read(&i.path).map_err(|e| format!("cannot read {}: {e}", i.path.display())))
        .collect::<Result<_, _>>()?;
    // Each input's `dynaflow` metadata: the run's provenance and its graph digest.
    let mut metas = Vec::new();
    for (input, buf) in inputs.iter().zip(&bufs) {
        // Read linearly, as `diff` and `compare` do: a cut recording (a killed machine) is
        // merged up to its cut.
        let mut meta = None;
        crate::mcap::scan::scan(buf, |event| {
            if let crate::mcap::scan::Event::Metadata(m) = event
                && m.name == "dynaflow"
            {
                meta = Some(m.metadata);
            }
            Ok(())
        })
        .map_err(|e| format!("{}: not a readable MCAP file: {e}", input.path.display()))?;
        let meta =
            meta.ok_or_else(|| format!("{}: no `dynaflow` metadata: not a dynaflow recording", input.path.display()))?;
        if meta.get("machine").is_none_or(String::is_empty) {
            return Err(format!(
                "{}: not written by `dynaflow run --machine NAME`: it holds a one-process run, which needs no merge",
                input.path.display()
            ));
        }
        metas.push(meta);
    }
    let key = |m: &BTreeMap<String, String>| (m.get("graph").cloned(), m.get("graph_digest").cloned());
    for (input, meta) in inputs.iter().zip(&metas).skip(1) {
        if key(meta) != key(&metas[0]) {
            return Err(format!(
                "{} is a recording of graph `{}` (digest {}), {} of `{}` (digest {}): merge the recordings of one run",
                input.path.display(),
                meta.get("graph").map_or("?", String::as_str),
                meta.get("graph_digest").map_or("?", String::as_str),
                inputs[0].path.display(),
                metas[0].get("graph").map_or("?", String::as_str),
                metas[0].get("graph_digest").map_or("?", String::as_str),
            ));
        }
    }
    let file = dynaflow_engine::files::create_new(out).map_err(|e| format!("cannot create {}: {e}", out.display()))?;
    let werr = |e: mcap::McapError| format!("writing {}: {e}", out.display());
    let mut writer = mcap::WriteOptions::new()
        .compression(Some(mcap::Compression::Zstd))
        .compression_level(1)
        .profile("")
        .library(format!("dynaflow {} (merge)", env!("CARGO_PKG_VERSION")))
        .create(std::io::BufWriter::new(file))
        .map_err(werr)?;
    let mut first = metas[0].clone();
    first.insert(
        "machines".into(),
        inputs.iter().map(|i| format!("{}={}", i.machine, i.path.display())).collect::<Vec<_>>().join(","),
    );
    first.insert("machine".into(), String::new());
    writer.write_metadata(&mcap::records::Metadata { name: "dynaflow".into(), metadata: first }).map_err(werr)?;
    for (input, meta) in inputs.iter().zip(&metas) {
        let name = format!("dynaflow.{}", input.machine);
        writer.write_metadata(&mcap::records::Metadata { name, metadata: meta.clone() }).map_err(werr)?;
    }
    // A k-way merge by log time (ties: input order, then file order).
    let mut streams = Vec::new();
    for (input, buf) in inputs.iter().zip(&bufs) {
        let s = mcap::MessageStream::new_with_options(buf, enumset::enum_set!(mcap::read::Options::IgnoreEndMagic))
            .map_err(|e| format!("{}: {e}", input.path.display()))?;
        streams.push(s.peekable());
    }
    let mut channels: BTreeMap<(usize, u16), u16> = BTreeMap::new();
    let mut written = 0u64;
    let mut cut = vec![false; streams.len()];
    loop {
        let mut best: Option<(u64, usize)> = None;
        for (i, s) in streams.iter_mut().enumerate() {
            if cut[i] {
                continue;
            }
            if let Some(Err(e)) = s.peek() {
                // The recording ends here (cut by a kill, or damaged): what came before is
                // merged, and the user told.
                eprintln!(
                    "warning: {}: read up to a cut or damage ({e}): the rest of it is not merged",
                    inputs[i].path.display()
                );
                cut[i] = true;
                continue;
            }
            if let Some(Ok(m)) = s.peek()
                && best.is_none_or(|(t, _)| m.log_time < t)
            {
                best = Some((m.log_time, i));
            }
        }
        let Some((_, i)) = best else { break };
        let Some(Ok(m)) = streams[i].next() else { break };
        let id = match channels.get(&(i, m.channel.id)) {
            Some(id) => *id,
            None => {
                let schema_id = match &m.channel.schema {
                    Some(s) => writer.add_schema(&s.name, &s.encoding, &s.data).map_err(werr)?,
                    None => 0,
                };
                let mut metadata = m.channel.metadata.clone();
                metadata.insert("machine".into(), inputs[i].machine.clone());
                let id = writer
                    .add_channel(schema_id, &m.channel.topic, &m.channel.message_encoding, &metadata)
                    .map_err(werr)?;
                channels.insert((i, m.channel.id), id);
                id
            }
        };
        let header = mcap::records::MessageHeader {
            channel_id: id,
            sequence: m.sequence,
            log_time: m.log_time,
            publish_time: m.publish_time,
        };
        writer.write_to_known_channel(&header, &m.data).map_err(werr)?;
        written += 1;
    }
    writer.finish().map_err(werr)?;
    Ok(written)
}

/// Merge `.rrd` recordings into `out`; returns the number of messages written.
pub fn merge_rrd(inputs: &[Input], out: &Path) -> Result<u64, String> {
    use rerun::external::re_log_encoding::{CrateVersion, DecoderApp, Encoder, EncodingOptions};
    use rerun::external::re_log_types::{LogMsg, StoreKind};
    check_machines(inputs, out)?;
    let file = dynaflow_engine::files::create_new(out).map_err(|e| format!("cannot create {}: {e}", out.display()))?;
    let mut encoder = Encoder::new_eager(
        CrateVersion::LOCAL,
        EncodingOptions::PROTOBUF_COMPRESSED,
        std::io::BufWriter::with_capacity(1 << 20, file),
    )
    .map_err(|e| format!("writing {}: {e}", out.display()))?;
    let mut recording = None;
    let mut app = None;
    let mut written = 0u64;
    for (k, input) in inputs.iter().enumerate() {
        let reader = std::fs::File::open(&input.path)
            .map(std::io::BufReader::new)
            .map_err(|e| format!("cannot read {}: {e}", input.path.display()))?;
        let decoder = DecoderApp::decode_eager(reader)
            .map_err(|e| format!("{}: not a readable .rrd file: {e}", input.path.display()))?;
        for msg in decoder {
            let mut msg = msg.map_err(|e| format!("{}: {e}", input.path.display()))?;
            let kind = msg.store_id().kind();
            if kind == StoreKind::Blueprint {
                // One layout: the first input's.
                if k > 0 {
                    continue;
                }
            } else {
                if let LogMsg::SetStoreInfo(info) = &msg {
                    let this_app = info.info.application_id().to_string();
                    match &app {
                        None => app = Some(this_app),
                        Some(a) if *a != this_app => {
                            return Err(format!(
                                "{} records application `{this_app}`, {} `{a}`: merge the recordings of one run",
                                input.path.display(),
                                inputs[0].path.display()
                            ));
                        }
                        Some(_) => {}
                    }
                    if recording.is_none() {
                        recording = Some(msg.store_id().clone());
                    } else {
                        continue;
                    }
                }
                if let Some(id) = &recording {
                    msg.set_store_id(id.clone());
                }
            }
            encoder.append(&msg).map_err(|e| format!("writing {}: {e}", out.display()))?;
            written += 1;
        }
    }
    encoder.finish().map_err(|e| format!("writing {}: {e}", out.display()))?;
    Ok(written)
}
