//! OctoMap's files, byte for byte (OctoMap 1.9's `AbstractOcTree::write`,
//! `AbstractOccupancyOcTree::writeBinary`, `OcTreeBaseImpl::writeNodesRecurs`,
//! `OccupancyOcTreeBase::writeBinaryNode`):
//!
//! - header lines: `# Octomap OcTree file` (`.ot`) or `# Octomap OcTree binary file` (`.bt`),
//!   a comment, `id OcTree|ColorOcTree`, `size N` (nodes), `res R`, `data`;
//! - `.ot`: depth first from the root, per node its log-odds (`f32`, little-endian), for a
//!   ColorOcTree its colour (3 bytes), then one byte whose bit `i` says child `i` exists;
//! - `.bt`: the tree at maximum likelihood and pruned, per node with children two bytes of
//!   two bits per child (`00` unknown, `10` free leaf, `01` occupied leaf, `11` inner; children
//!   0-3 in the first byte), then the inner children in order.

use std::path::Path;

use crate::Error;
use crate::key::DEPTH;
use crate::tree::{EXISTS, NONE, Node, OcTree, Params};

const OT_HEADER: &str = "# Octomap OcTree file";
const BT_HEADER: &str = "# Octomap OcTree binary file";
const COMMENT: &str = "# (feel free to add / change comments, but leave the first line as it is!)\n#\n";

/// `%g` with six significant digits, as C++'s default stream output of a double.
fn cpp_double(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let exp = v.abs().log10().floor() as i32;
    if (-4..6).contains(&exp) {
        let decimals = (5 - exp).max(0) as usize;
        let s = format!("{v:.decimals$}");
        if s.contains('.') { s.trim_end_matches('0').trim_end_matches('.').to_string() } else { s }
    } else {
        let s = format!("{v:.5e}");
        let (m, e) = s.split_once('e').unwrap_or((&s, "0"));
        let m = if m.contains('.') { m.trim_end_matches('0').trim_end_matches('.') } else { m };
        let e: i32 = e.parse().unwrap_or(0);
        format!("{m}e{}{:02}", if e < 0 { '-' } else { '+' }, e.abs())
    }
}

fn header(first: &str, id: &str, size: usize, res: f64) -> Vec<u8> {
    format!("{first}\n{COMMENT}id {id}\nsize {size}\nres {}\ndata\n", cpp_double(res)).into_bytes()
}

/// Average colour of the children that have one (OctoMap's `getAverageChildColor`).
fn average_color(t: &OcTree, n: &Node) -> Option<[u8; 3]> {
    let (mut sum, mut k) = ([0u32; 3], 0u32);
    for i in 0..8 {
        if let Some(c) = t.child(n, i) {
            // An inner child's colour is its own children's average (white without one), as
            // `updateInnerOccupancy` leaves it, bottom up.
            let c = if c.has_children() { average_color(t, c).unwrap_or([255; 3]) } else { c.color };
            if c != [255; 3] {
                for j in 0..3 {
                    sum[j] += u32::from(c[j]);
                }
                k += 1;
            }
        }
    }
    (k > 0).then(|| [(sum[0] / k) as u8, (sum[1] / k) as u8, (sum[2] / k) as u8])
}

fn write_node(t: &OcTree, n: &Node, color: bool, out: &mut Vec<u8>) {
    out.extend(n.log_odds.to_le_bytes());
    if color {
        let c = if n.has_children() { average_color(t, n).unwrap_or([255; 3]) } else { n.color };
        out.extend(c);
    }
    let mut bits = 0u8;
    for i in 0..8 {
        if t.child(n, i).is_some() {
            bits |= 1 << i;
        }
    }
    out.push(bits);
    for i in 0..8 {
        if let Some(c) = t.child(n, i) {
            write_node(t, c, color, out);
        }
    }
}

/// The `.ot` bytes of `tree`: a ColorOcTree when the tree is semantic, else an OcTree.
pub fn ot_bytes(tree: &OcTree) -> Vec<u8> {
    let color = tree.semantic();
    let id = if color { "ColorOcTree" } else { "OcTree" };
    let mut out = header(OT_HEADER, id, tree.size(), tree.params().resolution);
    if let Some(r) = tree.root() {
        write_node(tree, r, color, &mut out);
    }
    out
}

fn write_binary_node(t: &OcTree, n: &Node, out: &mut Vec<u8>) {
    let mut bytes = [0u8; 2];
    for i in 0..8 {
        if let Some(c) = t.child(n, i) {
            // Bit 2i: free or inner; bit 2i + 1: occupied or inner.
            let (free, occupied) = if c.has_children() {
                (1, 1)
            } else if t.is_occupied(c) {
                (0, 1)
            } else {
                (1, 0)
            };
            bytes[i / 4] |= (free << (2 * (i % 4))) | (occupied << (2 * (i % 4) + 1));
        }
    }
    out.extend(bytes);
    for i in 0..8 {
        if let Some(c) = t.child(n, i)
            && c.has_children()
        {
            write_binary_node(t, c, out);
        }
    }
}

/// The `.bt` bytes of `tree` (a maximum-likelihood, pruned copy, as OctoMap's `writeBinary`).
pub fn bt_bytes(tree: &OcTree) -> Vec<u8> {
    let mut t = tree.clone();
    t.to_max_likelihood();
    t.prune_all();
    let id = if t.semantic() { "ColorOcTree" } else { "OcTree" };
    let mut out = header(BT_HEADER, id, t.size(), t.params().resolution);
    if let Some(r) = t.root() {
        write_binary_node(&t, r, &mut out);
    }
    out
}

fn write_file(path: &Path, bytes: &[u8]) -> Result<(), Error> {
    // Write beside, then rename: an interrupted run never leaves half a file.
    // The temporary file is created new (`O_EXCL`), so a symlink planted at its name is an
    // error, never followed.
    let tmp = path.with_extension("partial");
    let _ = std::fs::remove_file(&tmp);
    std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&tmp)
        .and_then(|mut f| std::io::Write::write_all(&mut f, bytes))
        .and_then(|()| std::fs::rename(&tmp, path))
        .map_err(|e| Error::Io { path: path.display().to_string(), message: e.to_string() })
}

/// Write `tree` as an OctoMap `.ot` file.
pub fn write_ot(tree: &OcTree, path: &Path) -> Result<(), Error> {
    write_file(path, &ot_bytes(tree))
}

/// Write `tree` as an OctoMap `.bt` file.
pub fn write_bt(tree: &OcTree, path: &Path) -> Result<(), Error> {
    write_file(path, &bt_bytes(tree))
}

struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
    nodes: usize,
    limit: usize,
}

impl Reader<'_> {
    fn take(&mut self, n: usize) -> Result<&[u8], String> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.bytes.len());
        let end = end.ok_or_else(|| format!("truncated: data ends at byte {}", self.bytes.len()))?;
        let s = &self.bytes[self.at..end];
        self.at = end;
        Ok(s)
    }

    fn count(&mut self) -> Result<(), String> {
        self.nodes += 1;
        if self.nodes > self.limit {
            return Err(format!("more nodes than the header's size {}", self.limit));
        }
        Ok(())
    }
}

/// A node being read: its value and children (indices into `nodes`).
struct Raw {
    node: Node,
    kids: [Option<usize>; 8],
}

fn read_full(r: &mut Reader<'_>, color: bool, depth: u32, nodes: &mut Vec<Raw>) -> Result<usize, String> {
    if depth > DEPTH {
        return Err(format!("nodes nested deeper than {DEPTH} levels"));
    }
    r.count()?;
    let v = r.take(4)?;
    let log_odds = f32::from_le_bytes([v[0], v[1], v[2], v[3]]);
    if !log_odds.is_finite() {
        return Err(format!("a node's log-odds is {log_odds}"));
    }
    let mut node = Node { log_odds, ..Node::ABSENT };
    node.flags = EXISTS;
    if color {
        let c = r.take(3)?;
        node.color = [c[0], c[1], c[2]];
    }
    let bits = r.take(1)?[0];
    let me = nodes.len();
    nodes.push(Raw { node, kids: [None; 8] });
    for i in 0..8 {
        if bits & (1 << i) != 0 {
            let c = read_full(r, color, depth + 1, nodes)?;
            nodes[me].kids[i] = Some(c);
        }
    }
    Ok(me)
}

fn read_binary(
    r: &mut Reader<'_>,
    depth: u32,
    (lo, hi): (f32, f32),
    me: usize,
    nodes: &mut Vec<Raw>,
) -> Result<(), String> {
    if depth >= DEPTH {
        return Err(format!("nodes nested deeper than {DEPTH} levels"));
    }
    let b = r.take(2)?;
    let (b0, b1) = (b[0], b[1]);
    let mut inner = Vec::new();
    for i in 0..8 {
        let byte = if i < 4 { b0 } else { b1 };
        let bits = (byte >> (2 * (i % 4))) & 0b11;
        let value = match bits {
            0b01 => lo,
            0b10 => hi,
            0b11 => f32::NEG_INFINITY,
            _ => continue,
        };
        r.count()?;
        let mut node = Node { log_odds: value, ..Node::ABSENT };
        node.flags = EXISTS;
        nodes.push(Raw { node, kids: [None; 8] });
        let c = nodes.len() - 1;
        nodes[me].kids[i] = Some(c);
        if bits == 0b11 {
            inner.push(c);
        }
    }
    for c in inner {
        read_binary(r, depth + 1, (lo, hi), c, nodes)?;
        let max = nodes[c].kids.iter().flatten().map(|&k| nodes[k].node.log_odds).fold(f32::NEG_INFINITY, f32::max);
        nodes[c].node.log_odds = max;
    }
    Ok(())
}

/// Flatten read nodes into the tree's arena.
fn assemble(params: Params, semantic: bool, nodes: &[Raw]) -> Result<OcTree, String> {
    let mut blocks: Vec<[Node; 8]> = Vec::new();
    fn place(i: usize, nodes: &[Raw], blocks: &mut Vec<[Node; 8]>) -> Node {
        let mut n = nodes[i].node;
        n.children = NONE;
        if nodes[i].kids.iter().any(Option::is_some) {
            blocks.push([Node::ABSENT; 8]);
            let b = blocks.len() - 1;
            for (slot, k) in nodes[i].kids.iter().enumerate() {
                if let Some(k) = k {
                    let c = place(*k, nodes, blocks);
                    blocks[b][slot] = c;
                }
            }
            n.children = b as u32;
        }
        n
    }
    let root = if nodes.is_empty() { Node::ABSENT } else { place(0, nodes, &mut blocks) };
    OcTree::from_parts(params, semantic, root, blocks).map_err(|e| e.to_string())
}

/// Parse OctoMap file bytes (`.ot` or `.bt`, told apart by their first line); `name` is the
/// file's name for messages. Parameters other than the resolution are OctoMap's defaults.
pub fn parse(bytes: &[u8], name: &str) -> Result<OcTree, Error> {
    let bad = |m: String| Error::Format { path: name.to_string(), message: m };
    // Header: text lines up to `data`.
    let mut at = 0;
    let mut lines = Vec::new();
    loop {
        let end = bytes[at..]
            .iter()
            .position(|&b| b == b'\n')
            .ok_or_else(|| bad("no `data` line: not an OctoMap file, or truncated in its header".into()))?;
        let line = std::str::from_utf8(&bytes[at..at + end]).map_err(|_| bad("header is not text".into()))?;
        at += end + 1;
        let line = line.trim_end_matches('\r');
        if lines.is_empty() && !line.starts_with(OT_HEADER) && !line.starts_with(BT_HEADER) {
            return Err(bad(format!(
                "first line `{}` is not an OctoMap header",
                line.chars().take(40).collect::<String>()
            )));
        }
        lines.push(line.to_string());
        if line.trim() == "data" {
            break;
        }
        if lines.len() > 1000 {
            return Err(bad("header longer than 1000 lines".into()));
        }
    }
    let binary = lines[0].starts_with(BT_HEADER);
    let mut id = None;
    let mut size = None;
    let mut res = None;
    for l in &lines[1..] {
        if l.starts_with('#') || l.trim().is_empty() || l.trim() == "data" {
            continue;
        }
        let (k, v) = l.trim().split_once(' ').unwrap_or((l.trim(), ""));
        match k {
            "id" => id = Some(v.trim().to_string()),
            "size" => size = Some(v.trim().parse::<usize>().map_err(|_| bad(format!("bad size `{v}`")))?),
            "res" => res = Some(v.trim().parse::<f64>().map_err(|_| bad(format!("bad resolution `{v}`")))?),
            other => return Err(bad(format!("unknown header field `{other}`"))),
        }
    }
    let id = id.ok_or_else(|| bad("header has no `id`".into()))?;
    let res = res.ok_or_else(|| bad("header has no `res`".into()))?;
    let semantic = match id.as_str() {
        "OcTree" => false,
        "ColorOcTree" => true,
        other => return Err(bad(format!("tree type `{other}` (OcTree and ColorOcTree are read)"))),
    };
    let params = Params { resolution: res, ..Params::default() };
    params.check().map_err(|e| bad(e.to_string()))?;
    let data = &bytes[at..];
    // Each node takes at least one byte (a .bt node's children two bits): a size beyond
    // 8 nodes per byte cannot be true.
    let limit = size.unwrap_or(usize::MAX).min(data.len().saturating_mul(8) + 1);
    let mut r = Reader { bytes: data, at: 0, nodes: 0, limit };
    let mut nodes: Vec<Raw> = Vec::new();
    let tree = OcTree::new(params, semantic).map_err(|e| bad(e.to_string()))?;
    if !data.is_empty() {
        if binary {
            let (lo, hi) = tree.clamping();
            r.count().map_err(&bad)?;
            nodes.push(Raw { node: Node { log_odds: hi, flags: EXISTS, ..Node::ABSENT }, kids: [None; 8] });
            // The root stays at the upper clamp, as OctoMap reads it.
            read_binary(&mut r, 0, (lo, hi), 0, &mut nodes).map_err(&bad)?;
        } else {
            read_full(&mut r, semantic, 0, &mut nodes).map_err(&bad)?;
        }
    }
    if let Some(s) = size
        && s != r.nodes
    {
        return Err(bad(format!("header says {s} nodes, the data holds {}", r.nodes)));
    }
    if r.at != data.len() {
        return Err(bad(format!("{} bytes after the last node", data.len() - r.at)));
    }
    assemble(params, semantic, &nodes).map_err(&bad)
}

/// Read an OctoMap `.ot` or `.bt` file.
pub fn read(path: &Path) -> Result<OcTree, Error> {
    let bytes =
        std::fs::read(path).map_err(|e| Error::Io { path: path.display().to_string(), message: e.to_string() })?;
    parse(&bytes, &path.display().to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn doubles_print_as_cpp_streams_do() {
        assert_eq!(cpp_double(0.05), "0.05");
        assert_eq!(cpp_double(0.1), "0.1");
        assert_eq!(cpp_double(1.0), "1");
        assert_eq!(cpp_double(0.123456789), "0.123457");
        assert_eq!(cpp_double(0.00002), "2e-05");
        assert_eq!(cpp_double(1234567.0), "1.23457e+06");
    }

    fn sample(semantic: bool) -> OcTree {
        let mut t = OcTree::new(Params::default(), semantic).unwrap();
        let wall: Vec<[f32; 3]> =
            (0..30).flat_map(|i| (0..30).map(move |j| [1.5, -0.7 + i as f32 * 0.05, -0.7 + j as f32 * 0.05])).collect();
        let labels: Vec<crate::Label> =
            (0..wall.len()).map(|i| crate::Label { color: [i as u8, 7, 200], class: 3 }).collect();
        t.insert_scan(&wall, semantic.then_some(labels.as_slice()), [0.0, 0.1, 0.2], -1.0)
            .expect("within the memory budget");
        t
    }

    #[test]
    fn files_round_trip() {
        for semantic in [false, true] {
            let t = sample(semantic);
            let ot = ot_bytes(&t);
            let back = parse(&ot, "t.ot").unwrap();
            assert_eq!(back.size(), t.size());
            assert_eq!(ot_bytes(&back), ot, "semantic {semantic}");
            let bt = bt_bytes(&t);
            let back = parse(&bt, "t.bt").unwrap();
            assert_eq!(bt_bytes(&back), bt);
            let occupied = |t: &OcTree| t.occupied_leaves().len();
            let mut ml = t.clone();
            ml.to_max_likelihood();
            ml.prune_all();
            assert_eq!(occupied(&back), occupied(&ml));
        }
    }

    #[test]
    fn corrupt_and_truncated_files_are_errors() {
        let ot = ot_bytes(&sample(true));
        let bt = bt_bytes(&sample(false));
        for bytes in [&ot, &bt] {
            for cut in [0, 5, 30, 90, bytes.len() / 2, bytes.len() - 1] {
                let e = parse(&bytes[..cut], "cut.ot").unwrap_err().to_string();
                assert!(e.starts_with("cut.ot: "), "{e}");
            }
            let mut flipped = bytes.clone();
            for i in (120..flipped.len()).step_by(37) {
                flipped[i] ^= 0xa5;
                let _ = parse(&flipped, "flipped");
            }
            let mut extra = bytes.clone();
            extra.push(0);
            assert!(parse(&extra, "x").is_err());
        }
        assert!(parse(b"hello\nworld\n", "text").unwrap_err().to_string().contains("not an OctoMap header"));
        let odd = b"# Octomap OcTree file\nid CountingOcTree\nres 0.1\ndata\n";
        assert!(parse(odd, "c").unwrap_err().to_string().contains("CountingOcTree"));
        // A node claiming children 17 levels deep.
        let mut deep = header(OT_HEADER, "OcTree", 100, 0.1);
        for _ in 0..18 {
            deep.extend(0.0f32.to_le_bytes());
            deep.push(1);
        }
        assert!(parse(&deep, "deep").unwrap_err().to_string().contains("deeper"));
        assert!(matches!(read(Path::new("/nonexistent.ot")), Err(Error::Io { .. })));
    }
}
