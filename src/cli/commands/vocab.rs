//! `dynaflow vocab train`: a bag-of-words vocabulary for ORB descriptors from a set of images
//! (`dynaflow_slam::bow`, DBoW2's design).

use std::path::PathBuf;
use std::time::Instant;

use dynaflow_datasets::png::load_rgb;
use dynaflow_engine::msg::PixelFormat;
use dynaflow_slam::bow::Vocabulary;
use dynaflow_vision::GrayImage;
use dynaflow_vision::orb::{OrbConfig, OrbExtractor};

use crate::cli::{EXIT_BAD_INPUT, EXIT_FAILED, EXIT_OK};

/// `dynaflow vocab` commands.
#[derive(Debug, clap::Subcommand)]
pub enum VocabCommand {
    /// Train a vocabulary on the ORB descriptors of images (PNG or JPEG).
    Train(TrainArgs),
}

/// `dynaflow vocab train` arguments.
#[derive(Debug, clap::Args)]
pub struct TrainArgs {
    /// Training images.
    #[arg(required = true)]
    pub images: Vec<PathBuf>,
    /// Output file.
    #[arg(long)]
    pub out: PathBuf,
    /// Branching factor (DBoW2 and ORB-SLAM2: 10).
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u64).range(2..=64))]
    pub k: u64,
    /// Levels (ORB-SLAM2's vocabulary: 6; 5 gives up to 100,000 words).
    #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u64).range(1..=8))]
    pub levels: u64,
    /// ORB features per image (ORB-SLAM2's settings otherwise).
    #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u64).range(10..=100_000))]
    pub features: u64,
    /// Seed of the clustering.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

pub fn vocab(command: &VocabCommand) -> u8 {
    match command {
        VocabCommand::Train(args) => train(args),
    }
}

fn train(args: &TrainArgs) -> u8 {
    if let Err(e) =
        dynaflow_engine::files::refuse_overwriting_inputs("--out", &args.out, args.images.iter().map(PathBuf::as_path))
    {
        eprintln!("error: {e}");
        return EXIT_BAD_INPUT;
    }
    let t0 = Instant::now();
    let mut orb = OrbExtractor::new(OrbConfig { features: args.features as usize, ..OrbConfig::default() });
    let mut images = Vec::with_capacity(args.images.len());
    for path in &args.images {
        let img = match load_rgb(path) {
            Ok(i) => i,
            Err(e) => {
                eprintln!("error: {e}");
                return EXIT_BAD_INPUT;
            }
        };
        let (w, h) = (img.width as usize, img.height as usize);
        let gray = match img.format {
            PixelFormat::Gray8 => Some(GrayImage { width: w, height: h, data: img.data }),
            _ => GrayImage::from_rgb8(w, h, &img.data),
        };
        let Some(gray) = gray else {
            eprintln!("error: {}: not an 8-bit RGB or grey image", path.display());
            return EXIT_BAD_INPUT;
        };
        images.push(orb.extract(&gray, None).descriptors);
    }
    let (voc, stats) = match Vocabulary::train(&images, args.k as usize, args.levels as usize, args.seed) {
        Ok(v) => v,
        Err(e) => {
            eprintln!("error: {e}");
            return EXIT_BAD_INPUT;
        }
    };
    // A vocabulary with fewer words than two of its levels would hold cannot tell places apart
    // (threshold chosen: k^2, e.g. 100 for k 10; ORB-SLAM2's holds about a million words).
    let few = (args.k * args.k) as usize;
    if stats.words < few {
        eprintln!(
            "warning: only {} words from {} descriptors (fewer than k^2 = {few}): too few to tell places apart; train on more, or larger, images",
            stats.words, stats.descriptors
        );
    }
    if let Err(e) = dynaflow_engine::files::write_atomic(&args.out, &voc.to_bytes()) {
        eprintln!("error: cannot write {}: {e}", args.out.display());
        return EXIT_FAILED;
    }
    println!(
        "vocabulary {} (k {}, {} levels): {} words, {} nodes, from {} descriptors of {} images in {:.1} s -> {}",
        voc.id(),
        args.k,
        args.levels,
        stats.words,
        stats.nodes,
        stats.descriptors,
        stats.images,
        t0.elapsed().as_secs_f64(),
        args.out.display()
    );
    EXIT_OK
}
