//! A bag-of-binary-words vocabulary for ORB descriptors, as DBoW2 builds and uses one
//! (Gálvez-López and Tardós, "Bags of Binary Words for Fast Place Recognition in Image
//! Sequences", T-RO 2012), written from the paper:
//!
//! - **Training** ([`Vocabulary::train`]): hierarchical k-medians on the descriptors of a set of
//!   training images, `k` branches and `levels` levels (ORB-SLAM2's vocabulary: k = 10, L = 6),
//!   each level seeded by k-means++ on Hamming distance, centres updated as the bitwise
//!   majority of their cluster (the binary mean), until assignments stop changing; the leaves
//!   are the words. Each word is weighted by its inverse document frequency `ln(N / n_i)` over
//!   the `N` training images (`n_i` of which contain it).
//! - **Use** ([`Vocabulary::transform`]): a descriptor descends the tree to the closest child at
//!   each level; an image is the L1-normalised vector of tf-idf weights of its words, and the
//!   features grouped by their node `levels_up` above the words (the direct index that
//!   ORB-SLAM2's `SearchByBoW` matches within).
//! - **Similarity** ([`score`]): DBoW2's L1 score `1 - |v/|v| - w/|w||_1 / 2`, in [0, 1].
//! - **Files** ([`Vocabulary::to_bytes`], [`Vocabulary::load`]): a versioned little-endian binary
//!   format with a checksum; [`Vocabulary::id`] names its content (a saved map records the id of
//!   the vocabulary it was built with).
//!
//! Deterministic: a training seed fixes every choice.

use std::collections::BTreeMap;
use std::path::Path;

use dynaflow_vision::geometry::SplitMix64;
use dynaflow_vision::matching::hamming;

/// A binary descriptor (ORB: 256 bits).
pub type Descriptor = [u8; 32];

/// Bag-of-words vector: word id to weight, L1-normalised.
pub type BowVector = BTreeMap<u32, f64>;

/// Direct index: node id to the indices of the features below it.
pub type FeatureVector = BTreeMap<u32, Vec<u32>>;

/// Why a vocabulary cannot be trained, read or written.
#[derive(Debug, thiserror::Error)]
pub enum BowError {
    /// The file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// What the system said.
        source: std::io::Error,
    },
    /// No `DFVOCAB` header.
    #[error("{path}: not a dynaflow vocabulary (no `DFVOCAB` header)")]
    NotAVocabulary {
        /// The file.
        path: String,
    },
    /// A format version this build does not read.
    #[error("{path}: vocabulary format version {found}; this build reads version {FORMAT_VERSION}")]
    Version {
        /// The file.
        path: String,
        /// Its version.
        found: u32,
    },
    /// Shorter than its header says.
    #[error("{path}: truncated ({len} bytes; the header promises {expected})")]
    Truncated {
        /// The file.
        path: String,
        /// Its length, bytes.
        len: usize,
        /// What the header promises, bytes.
        expected: usize,
    },
    /// The checksum does not match.
    #[error("{path}: corrupt (checksum {found:016x}, the file says {expected:016x})")]
    Checksum {
        /// The file.
        path: String,
        /// The checksum of its contents.
        found: u64,
        /// The checksum it stores.
        expected: u64,
    },
    /// Contents that cannot be a vocabulary.
    #[error("{path}: corrupt: {what}")]
    Corrupt {
        /// The file.
        path: String,
        /// What is wrong.
        what: String,
    },
    /// Training was given too little.
    #[error("cannot train a vocabulary: {0}")]
    Training(String),
}

const MAGIC: &[u8; 8] = b"DFVOCAB\0";
/// The file format's version.
pub const FORMAT_VERSION: u32 = 1;
/// Header: magic, version, k, levels, node count.
const HEADER: usize = 8 + 4 * 4;
/// A node: parent (u32), word id + 1 or 0 (u32), weight (f64), descriptor (32 bytes).
const NODE: usize = 4 + 4 + 8 + 32;
/// k-medians iterations at most per node (DBoW2 iterates to convergence; a cap bounds
/// pathological inputs).
const MAX_ITERATIONS: usize = 30;

#[derive(Clone, Debug, PartialEq)]
struct Node {
    parent: u32,
    descriptor: Descriptor,
    children: Vec<u32>,
    word: Option<u32>,
    /// The word's idf weight (0 for inner nodes).
    weight: f64,
}

/// A trained vocabulary tree.
#[derive(Clone, Debug, PartialEq)]
pub struct Vocabulary {
    k: usize,
    levels: usize,
    /// Node 0 is the root (no descriptor).
    nodes: Vec<Node>,
    /// Node index of each word.
    words: Vec<u32>,
}

/// What [`Vocabulary::train`] saw.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrainingStats {
    /// Images trained on.
    pub images: usize,
    /// Descriptors clustered.
    pub descriptors: usize,
    /// Leaves (words).
    pub words: usize,
    /// Nodes of the tree.
    pub nodes: usize,
}

/// FNV-1a, 64 bits.
fn fnv(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &b| (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3))
}

/// The bitwise majority of `members` (ties give 0, as DBoW2's binary mean).
fn majority(descriptors: &[Descriptor], members: &[usize]) -> Descriptor {
    let mut counts = [0u32; 256];
    for &m in members {
        for (byte, &v) in descriptors[m].iter().enumerate() {
            for bit in 0..8 {
                counts[byte * 8 + bit] += u32::from((v >> bit) & 1);
            }
        }
    }
    let mut out = [0u8; 32];
    let half = members.len() as u32;
    for (i, &c) in counts.iter().enumerate() {
        if 2 * c > half {
            out[i / 8] |= 1 << (i % 8);
        }
    }
    out
}

/// k-means++ seeding on Hamming distance: `k` distinct members as initial centres.
fn seed_centres(descriptors: &[Descriptor], members: &[usize], k: usize, rng: &mut SplitMix64) -> Vec<Descriptor> {
    let mut centres = vec![descriptors[members[rng.below(members.len())]]];
    let mut d2: Vec<f64> = members.iter().map(|&m| f64::from(hamming(&descriptors[m], &centres[0])).powi(2)).collect();
    while centres.len() < k {
        let total: f64 = d2.iter().sum();
        if total <= 0.0 {
            break; // every member equals a centre: fewer distinct clusters than k
        }
        let mut r = rng.uniform() * total;
        let mut pick = members.len() - 1;
        for (i, &d) in d2.iter().enumerate() {
            if r < d {
                pick = i;
                break;
            }
            r -= d;
        }
        let c = descriptors[members[pick]];
        for (d, &m) in d2.iter_mut().zip(members) {
            *d = d.min(f64::from(hamming(&descriptors[m], &c)).powi(2));
        }
        centres.push(c);
    }
    centres
}

fn nearest(centres: &[Descriptor], d: &Descriptor) -> usize {
    let mut best = (u32::MAX, 0);
    for (i, c) in centres.iter().enumerate() {
        let h = hamming(c, d);
        if h < best.0 {
            best = (h, i);
        }
    }
    best.1
}

impl Vocabulary {
    /// Train on the descriptors of each training image: `k` branches, `levels` levels, `seed`.
    pub fn train(
        images: &[Vec<Descriptor>],
        k: usize,
        levels: usize,
        seed: u64,
    ) -> Result<(Self, TrainingStats), BowError> {
        if !(2..=64).contains(&k) || !(1..=8).contains(&levels) {
            return Err(BowError::Training(format!("k {k} must be in 2..=64 and levels {levels} in 1..=8")));
        }
        let descriptors: Vec<Descriptor> = images.iter().flatten().copied().collect();
        if descriptors.is_empty() {
            return Err(BowError::Training("the training images have no descriptors".into()));
        }
        let mut rng = SplitMix64::new(seed);
        let mut nodes = vec![Node { parent: 0, descriptor: [0; 32], children: Vec::new(), word: None, weight: 0.0 }];
        // (node, depth, members) to split, depth first in node order: deterministic.
        let mut stack: Vec<(u32, usize, Vec<usize>)> = vec![(0, 0, (0..descriptors.len()).collect())];
        while let Some((node, depth, members)) = stack.pop() {
            let clusters: Vec<(Descriptor, Vec<usize>)> = if members.len() <= k {
                // DBoW2: as many clusters as members, each its own centre.
                members.iter().map(|&m| (descriptors[m], vec![m])).collect()
            } else {
                let mut centres = seed_centres(&descriptors, &members, k, &mut rng);
                let mut assign: Vec<usize> = vec![usize::MAX; members.len()];
                for _ in 0..MAX_ITERATIONS {
                    let next: Vec<usize> = members.iter().map(|&m| nearest(&centres, &descriptors[m])).collect();
                    if next == assign {
                        break;
                    }
                    assign = next;
                    for (c, centre) in centres.iter_mut().enumerate() {
                        let cluster: Vec<usize> =
                            members.iter().zip(&assign).filter(|(_, a)| **a == c).map(|(&m, _)| m).collect();
                        if !cluster.is_empty() {
                            *centre = majority(&descriptors, &cluster);
                        }
                    }
                }
                centres
                    .iter()
                    .enumerate()
                    .map(|(c, centre)| {
                        (*centre, members.iter().zip(&assign).filter(|(_, a)| **a == c).map(|(&m, _)| m).collect())
                    })
                    .filter(|(_, m): &(Descriptor, Vec<usize>)| !m.is_empty())
                    .collect()
            };
            let mut pushed = Vec::new();
            for (centre, cluster) in clusters {
                let id = nodes.len() as u32;
                nodes.push(Node { parent: node, descriptor: centre, children: Vec::new(), word: None, weight: 0.0 });
                nodes[node as usize].children.push(id);
                if depth + 1 < levels && cluster.len() > 1 {
                    pushed.push((id, depth + 1, cluster));
                }
            }
            // Reverse so that the first child is split first.
            stack.extend(pushed.into_iter().rev());
        }
        let mut words = Vec::new();
        for (i, n) in nodes.iter_mut().enumerate().skip(1) {
            if n.children.is_empty() {
                n.word = Some(words.len() as u32);
                words.push(i as u32);
            }
        }
        let mut voc = Self { k, levels, nodes, words };
        // idf: ln(N / n_i) over the training images (0 for a word no image contains).
        let mut containing = vec![0usize; voc.words.len()];
        for image in images {
            let mut seen: Vec<u32> = image.iter().map(|d| voc.word_of(d).0).collect();
            seen.sort_unstable();
            seen.dedup();
            for w in seen {
                containing[w as usize] += 1;
            }
        }
        let n = images.len() as f64;
        for (w, &c) in containing.iter().enumerate() {
            let node = voc.words[w] as usize;
            voc.nodes[node].weight = if c > 0 { (n / c as f64).ln() } else { 0.0 };
        }
        let stats = TrainingStats {
            images: images.len(),
            descriptors: descriptors.len(),
            words: voc.words.len(),
            nodes: voc.nodes.len(),
        };
        Ok((voc, stats))
    }

    /// Branching factor.
    pub fn k(&self) -> usize {
        self.k
    }

    /// Depth of the tree.
    pub fn levels(&self) -> usize {
        self.levels
    }

    /// Number of words.
    pub fn words(&self) -> usize {
        self.words.len()
    }

    /// A word's idf weight.
    pub fn weight(&self, word: u32) -> f64 {
        self.words.get(word as usize).map_or(0.0, |&n| self.nodes[n as usize].weight)
    }

    /// The word of a descriptor and the node `levels_up` above it on its path (the word's
    /// own node for 0, the root's child for `levels - 1` or more).
    fn word_and_node(&self, d: &Descriptor, levels_up: usize) -> (u32, u32) {
        let mut path = Vec::with_capacity(self.levels);
        let mut node = 0usize;
        loop {
            let children = &self.nodes[node].children;
            if children.is_empty() {
                break;
            }
            let mut best = (u32::MAX, children[0]);
            for &c in children {
                let h = hamming(&self.nodes[c as usize].descriptor, d);
                if h < best.0 {
                    best = (h, c);
                }
            }
            node = best.1 as usize;
            path.push(node as u32);
        }
        let word = self.nodes[node].word.unwrap_or(0);
        let up = path.len().saturating_sub(1 + levels_up);
        (word, path.get(up).copied().unwrap_or(0))
    }

    /// The word of a descriptor, and its node.
    pub fn word_of(&self, d: &Descriptor) -> (u32, u32) {
        self.word_and_node(d, 0)
    }

    /// An image's bag of words (tf-idf, L1-normalised) and its features grouped by the node
    /// `levels_up` above their words (ORB-SLAM2 uses 4 with L = 6).
    pub fn transform(&self, descriptors: &[Descriptor], levels_up: usize) -> (BowVector, FeatureVector) {
        let mut bow = BowVector::new();
        let mut features = FeatureVector::new();
        for (i, d) in descriptors.iter().enumerate() {
            let (w, node) = self.word_and_node(d, levels_up);
            let weight = self.weight(w);
            if weight > 0.0 {
                *bow.entry(w).or_default() += weight;
            }
            features.entry(node).or_default().push(i as u32);
        }
        let sum: f64 = bow.values().sum();
        if sum > 0.0 {
            for v in bow.values_mut() {
                *v /= sum;
            }
        }
        (bow, features)
    }

    /// The file's bytes (`dynaflow vocab train` writes them as a new file renamed into place).
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut b = Vec::with_capacity(HEADER + NODE * self.nodes.len() + 8);
        b.extend_from_slice(MAGIC);
        for v in [FORMAT_VERSION, self.k as u32, self.levels as u32, self.nodes.len() as u32] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        for n in &self.nodes {
            b.extend_from_slice(&n.parent.to_le_bytes());
            b.extend_from_slice(&n.word.map_or(0, |w| w + 1).to_le_bytes());
            b.extend_from_slice(&n.weight.to_le_bytes());
            b.extend_from_slice(&n.descriptor);
        }
        let sum = fnv(&b);
        b.extend_from_slice(&sum.to_le_bytes());
        b
    }

    /// The content's id (the checksum of its file), hex.
    pub fn id(&self) -> String {
        let b = self.to_bytes();
        let mut tail = [0u8; 8];
        tail.copy_from_slice(&b[b.len() - 8..]);
        format!("{:016x}", u64::from_le_bytes(tail))
    }

    /// Read from `path`; every inconsistency is an error naming the file.
    pub fn load(path: &Path) -> Result<Self, BowError> {
        let p = path.display().to_string();
        let b = std::fs::read(path).map_err(|source| BowError::Io { path: p.clone(), source })?;
        Self::from_bytes(&b, &p)
    }

    /// Read from the bytes of a vocabulary file; `p` names it in errors.
    pub fn from_bytes(b: &[u8], p: &str) -> Result<Self, BowError> {
        if b.len() < MAGIC.len() || &b[..MAGIC.len()] != MAGIC {
            return Err(BowError::NotAVocabulary { path: p.into() });
        }
        if b.len() < HEADER {
            return Err(BowError::Truncated { path: p.into(), len: b.len(), expected: HEADER });
        }
        let u32_at = |o: usize| u32::from_le_bytes([b[o], b[o + 1], b[o + 2], b[o + 3]]);
        let version = u32_at(8);
        if version != FORMAT_VERSION {
            return Err(BowError::Version { path: p.into(), found: version });
        }
        let (k, levels, count) = (u32_at(12) as usize, u32_at(16) as usize, u32_at(20) as usize);
        let expected = count.checked_mul(NODE).and_then(|n| n.checked_add(HEADER + 8)).unwrap_or(usize::MAX);
        if b.len() != expected {
            return Err(BowError::Truncated { path: p.into(), len: b.len(), expected });
        }
        let body = &b[..b.len() - 8];
        let mut tail = [0u8; 8];
        tail.copy_from_slice(&b[b.len() - 8..]);
        let (found, stored) = (fnv(body), u64::from_le_bytes(tail));
        if found != stored {
            return Err(BowError::Checksum { path: p.into(), found, expected: stored });
        }
        let corrupt = |what: String| BowError::Corrupt { path: p.into(), what };
        if count == 0 || !(2..=64).contains(&k) || !(1..=8).contains(&levels) {
            return Err(corrupt(format!("k {k}, levels {levels}, {count} nodes")));
        }
        let mut nodes = Vec::with_capacity(count);
        let mut words = Vec::new();
        for i in 0..count {
            let o = HEADER + i * NODE;
            let parent = u32_at(o);
            let word = u32_at(o + 4);
            let mut w = [0u8; 8];
            w.copy_from_slice(&b[o + 8..o + 16]);
            let weight = f64::from_le_bytes(w);
            let mut descriptor = [0u8; 32];
            descriptor.copy_from_slice(&b[o + 16..o + 48]);
            if i > 0 && parent as usize >= i {
                return Err(corrupt(format!("node {i} has parent {parent}, not an earlier node")));
            }
            if !weight.is_finite() || weight < 0.0 {
                return Err(corrupt(format!("node {i} has weight {weight}")));
            }
            if word > 0 {
                if word as usize - 1 != words.len() {
                    return Err(corrupt(format!("node {i} is word {}, expected {}", word - 1, words.len())));
                }
                words.push(i as u32);
            }
            nodes.push(Node { parent, descriptor, children: Vec::new(), word: word.checked_sub(1), weight });
        }
        for i in 1..count {
            let parent = nodes[i].parent as usize;
            nodes[parent].children.push(i as u32);
        }
        for (i, n) in nodes.iter().enumerate() {
            if n.children.is_empty() != n.word.is_some() && i > 0 {
                return Err(corrupt(format!("node {i}: a leaf must be a word and a word a leaf")));
            }
        }
        if words.is_empty() {
            return Err(corrupt("no word: a vocabulary needs at least one leaf to put descriptors in".into()));
        }
        Ok(Self { k, levels, nodes, words })
    }
}

/// DBoW2's L1 similarity of two L1-normalised bags of words: 1 for the same words in the same
/// proportions, 0 for no word in common.
pub fn score(a: &BowVector, b: &BowVector) -> f64 {
    // |a - b|_1 = |a|_1 + |b|_1 + sum over common words of (|a_w - b_w| - a_w - b_w).
    let mut common = 0.0;
    for (w, &x) in a {
        if let Some(&y) = b.get(w) {
            common += (x - y).abs() - x - y;
        }
    }
    let (na, nb): (f64, f64) = (a.values().sum(), b.values().sum());
    if na <= 0.0 || nb <= 0.0 {
        return 0.0;
    }
    (1.0 - 0.5 * (na + nb + common)).clamp(0.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `clusters` random centres, `per` noisy copies of each (up to `noise` flipped bits) per image.
    fn clustered(
        clusters: usize,
        per: usize,
        images: usize,
        noise: usize,
        seed: u64,
    ) -> (Vec<Descriptor>, Vec<Vec<Descriptor>>) {
        let mut rng = SplitMix64::new(seed);
        let centres: Vec<Descriptor> =
            (0..clusters).map(|_| std::array::from_fn(|_| (rng.next_u64() & 0xff) as u8)).collect();
        let imgs = (0..images)
            .map(|_| {
                let mut v = Vec::new();
                for c in &centres {
                    for _ in 0..per {
                        let mut d = *c;
                        for _ in 0..rng.below(noise + 1) {
                            let bit = rng.below(256);
                            d[bit / 8] ^= 1 << (bit % 8);
                        }
                        v.push(d);
                    }
                }
                v
            })
            .collect();
        (centres, imgs)
    }

    #[test]
    fn one_level_recovers_well_separated_clusters_as_words() {
        let (centres, images) = clustered(6, 20, 3, 6, 1);
        let (voc, stats) = Vocabulary::train(&images, 6, 1, 7).unwrap();
        assert_eq!((stats.words, stats.images, stats.descriptors), (6, 3, 360));
        // Every noisy copy of a centre lands in that centre's word, and the words differ.
        let words: Vec<u32> = centres.iter().map(|c| voc.word_of(c).0).collect();
        let mut distinct = words.clone();
        distinct.sort_unstable();
        distinct.dedup();
        assert_eq!(distinct.len(), 6, "{words:?}");
        for (img, c) in images[0].chunks(20).zip(&words) {
            assert!(img.iter().all(|d| voc.word_of(d).0 == *c));
        }
        // Every word is in every image: idf ln(3/3) = 0; so no word has a weight.
        assert!((0..6).all(|w| voc.weight(w) == 0.0));
    }

    #[test]
    fn scores_are_one_for_the_same_image_and_zero_for_no_common_word() {
        let (_, mut images) = clustered(40, 5, 4, 4, 2);
        // Image 3 keeps only the last 20 clusters; image 0 only the first 20.
        images[0].truncate(100);
        images[3].drain(..100);
        let (voc, stats) = Vocabulary::train(&images, 10, 2, 3).unwrap();
        assert!(stats.words >= 40, "{stats:?}");
        let (a, fa) = voc.transform(&images[0], 1);
        let (b, _) = voc.transform(&images[3], 1);
        assert!((a.values().sum::<f64>() - 1.0).abs() < 1e-12);
        assert!((score(&a, &a) - 1.0).abs() < 1e-12);
        assert!(score(&a, &b) < 0.05, "{}", score(&a, &b));
        // The direct index holds every feature once.
        assert_eq!(fa.values().map(Vec::len).sum::<usize>(), images[0].len());
    }

    #[test]
    fn training_is_deterministic_and_a_file_round_trips_or_is_refused() {
        let (_, images) = clustered(30, 4, 3, 8, 4);
        let (a, _) = Vocabulary::train(&images, 5, 3, 11).unwrap();
        let (b, _) = Vocabulary::train(&images, 5, 3, 11).unwrap();
        assert_eq!(a, b);
        assert_eq!(a.id(), b.id());
        let bytes = a.to_bytes();
        assert_eq!(Vocabulary::from_bytes(&bytes, "v").unwrap(), a);
        let e = Vocabulary::from_bytes(&bytes[..bytes.len() - 9], "v").unwrap_err();
        assert!(matches!(e, BowError::Truncated { .. }), "{e}");
        let mut flipped = bytes.clone();
        flipped[HEADER + 20] ^= 1;
        assert!(matches!(Vocabulary::from_bytes(&flipped, "v").unwrap_err(), BowError::Checksum { .. }));
        assert!(matches!(Vocabulary::from_bytes(b"ORBvoc", "v").unwrap_err(), BowError::NotAVocabulary { .. }));
        let mut v2 = bytes;
        v2[8] = 2;
        assert!(matches!(Vocabulary::from_bytes(&v2, "v").unwrap_err(), BowError::Version { found: 2, .. }));
        assert!(matches!(Vocabulary::train(&[], 10, 5, 0).unwrap_err(), BowError::Training(_)));
    }
}
