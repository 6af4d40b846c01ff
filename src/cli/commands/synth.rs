//! `dynaflow synth`: write a generated sequence as a TUM RGB-D folder, a KITTI odometry
//! stereo sequence or a EuRoC MAV folder (cameras, depth, IMU, ground truth).

use std::path::PathBuf;
use std::time::Instant;

use dynaflow_datasets::synth::{
    EurocWriteOptions, Generator, KittiWriteOptions, Motion, PeopleMode, SynthConfig, WriteOptions, fisheye,
    rig_calibration, scaled_fr3, scaled_kitti, write_euroc, write_kitti, write_tum,
};

use crate::cli::{EXIT_BAD_INPUT, EXIT_FAILED, EXIT_OK};

/// `dynaflow synth` arguments.
#[derive(Debug, clap::Args)]
pub struct SynthArgs {
    /// Camera motion (`drive`: a car round a city block in the street scene, KITTI's camera;
    /// with `--people 0`, `--rate-hz 10`, `--width 1241 --height 376` for KITTI's own).
    #[arg(long, default_value = "xyz", value_parser = clap::builder::PossibleValuesParser::new(Motion::NAMES))]
    pub motion: String,
    /// Number of people.
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u64).range(0..=16))]
    pub people: u64,
    /// People sit and move little (like TUM `sitting_*`).
    #[arg(long)]
    pub sitting: bool,
    /// Number of frames.
    #[arg(long, default_value_t = 300, value_parser = clap::value_parser!(u64).range(1..=1_000_000))]
    pub frames: u64,
    /// Scene and noise seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Frame rate, Hz.
    #[arg(long, default_value_t = 30.0)]
    pub rate_hz: f64,
    /// Image width (intrinsics are TUM fr3 scaled to it; KITTI's for `--motion drive`).
    #[arg(long, default_value_t = 640, value_parser = clap::value_parser!(u32).range(16..=4096))]
    pub width: u32,
    /// Image height.
    #[arg(long, default_value_t = 480, value_parser = clap::value_parser!(u32).range(16..=4096))]
    pub height: u32,
    /// A Kannala-Brandt fisheye (TUM-VI's lens, 123 degrees across at 640x480) instead of the
    /// fr3 pinhole; written as `kb:...` in calibration.txt, Kalibr's `equidistant` in EuRoC.
    #[arg(long)]
    pub fisheye: bool,
    /// Also write ground-truth optical flow (`flow/*.flo`).
    #[arg(long)]
    pub flow: bool,
    /// Kidnap the camera at this frame: 30 black frames without depth, then the motion resumes
    /// 10 s earlier (a place already seen; relocalisation)
    #[arg(long)]
    pub kidnap: Option<u64>,
    /// Cover the camera at this frame: black frames without depth while the motion goes on
    /// (the IMU keeps measuring: a visual blackout)
    #[arg(long)]
    pub blackout: Option<u64>,
    /// Frames a `--blackout` lasts.
    #[arg(long, default_value_t = dynaflow_datasets::synth::KIDNAP_BLACKOUT, value_parser = clap::value_parser!(u64).range(1..))]
    pub blackout_frames: u64,
    /// No depth noise, image noise or blur (exact rendering).
    #[arg(long)]
    pub clean: bool,
    /// Layout: `tum` (RGB-D: rgb/, depth/, ground truth, masks), `kitti` (a rectified stereo
    /// pair in the KITTI odometry layout: OUT/sequences/00 and OUT/poses/00.txt) or `euroc`
    /// (EuRoC MAV: OUT/mav0 with cam0, a rectified cam1, depth0, a 200 Hz ADIS16448-like imu0
    /// and the body's ground truth; use `--motion handheld` for visual-inertial runs).
    #[arg(long, default_value = "tum", value_parser = ["tum", "kitti", "euroc"])]
    pub format: String,
    /// Stereo baseline in metres for `--format kitti` and `euroc` (12 cm: a ZED-class rig at
    /// room scale; KITTI's own rig is 54 cm, for street depths).
    #[arg(long, default_value_t = 0.12)]
    pub baseline: f64,
    /// Output folder. Name it `rgbd_dataset_freiburg3_*` and TUM tools pick fr3 intrinsics
    /// from the name; `tum_rgbd` also reads the `calibration.txt` written here.
    #[arg(long)]
    pub out: PathBuf,
}

pub fn synth(args: &SynthArgs) -> u8 {
    let Some(motion) = Motion::from_name(&args.motion) else {
        eprintln!("error: unknown motion `{}`", args.motion);
        return EXIT_BAD_INPUT;
    };
    let config = SynthConfig {
        motion,
        people: args.people as usize,
        mode: if args.sitting { PeopleMode::Sitting } else { PeopleMode::Walking },
        seed: args.seed,
        rate_hz: args.rate_hz,
        intrinsics: if args.fisheye {
            fisheye(args.width, args.height)
        } else if motion == Motion::Drive {
            scaled_kitti(args.width, args.height)
        } else {
            scaled_fr3(args.width, args.height)
        },
        depth_noise: !args.clean,
        image_noise: if args.clean { 0.0 } else { 2.0 },
        blur: !args.clean,
        kidnap: args.kidnap,
        blackout: args.blackout,
        blackout_frames: args.blackout_frames,
    };
    if motion == Motion::Drive && args.people > 0 {
        eprintln!("error: `--motion drive`: the street has no people yet; add `--people 0`");
        return EXIT_BAD_INPUT;
    }
    if !(args.rate_hz > 0.0 && args.rate_hz <= 1000.0) {
        eprintln!("error: `--rate-hz {}`: a frame rate in (0, 1000] Hz", args.rate_hz);
        return EXIT_BAD_INPUT;
    }
    let t = Instant::now();
    let generator = Generator::new(config);
    if args.format != "tum" {
        if args.flow {
            eprintln!(
                "error: `--flow` writes TUM-layout extras; {} has no flow (drop `--flow` or use `--format tum`)",
                args.format
            );
            return EXIT_BAD_INPUT;
        }
        if !(args.baseline > 0.0 && args.baseline.is_finite()) {
            eprintln!("error: `--baseline {}`: a stereo baseline must be positive metres", args.baseline);
            return EXIT_BAD_INPUT;
        }
    }
    if args.format == "euroc" && args.kidnap.is_some() {
        eprintln!(
            "error: `--kidnap` rewinds the camera, a jump no IMU measures; the EuRoC layout is written without one"
        );
        return EXIT_BAD_INPUT;
    }
    let written = if args.format == "euroc" {
        let opts = EurocWriteOptions {
            frames: args.frames,
            baseline: Some(args.baseline),
            depth: true,
            calibration: rig_calibration(),
        };
        write_euroc(&generator, &args.out, &opts)
            .map(|root| eprintln!("EuRoC MAV folder {}", root.join("mav0").display()))
    } else if args.format == "kitti" {
        write_kitti(&generator, &args.out, &KittiWriteOptions { frames: args.frames, baseline: args.baseline }).map(
            |seq| eprintln!("KITTI sequence {} (poses {})", seq.display(), args.out.join("poses/00.txt").display()),
        )
    } else {
        write_tum(&generator, &args.out, &WriteOptions { frames: args.frames, flow: args.flow })
    };
    match written {
        Ok(()) => {
            let s = t.elapsed().as_secs_f64();
            eprintln!(
                "wrote {} frames to {} in {s:.1} s ({:.1} frames/s)",
                args.frames,
                args.out.display(),
                args.frames as f64 / s
            );
            EXIT_OK
        }
        Err(e) => {
            eprintln!("error: {e}");
            EXIT_FAILED
        }
    }
}
