//! `bitt detect-hands`: find both hands in a photo with the built-in detector; writes
//! `keypoints.json`, `detection.json` and `overlay.png`. And `bitt convert-mediapipe`: the
//! detector's weights file from MediaPipe's wheel.

use std::path::PathBuf;

use anyhow::Result;

use crate::device::DeviceName;

/// Arguments of `bitt detect-hands`.
#[derive(Debug, clap::Args)]
pub struct DetectHandsArgs {
    /// A photo of two hands (PNG or JPEG, any size).
    #[arg(long)]
    pub image: PathBuf,
    /// Output folder: keypoints.json (plain keypoints; `fit-hands --keypoints` and
    /// `train-scene --keypoints` read it), detection.json (scores, stages, seconds) and
    /// overlay.png (each hand's keypoints and bones, left orange, right blue). A folder that
    /// exists, is not empty and holds no detection.json is refused.
    #[arg(long, default_value = "runs/detect-hands")]
    pub out: PathBuf,
    /// Backend the detector runs on.
    #[arg(long, value_enum, default_value = "flex")]
    pub device: DeviceName,
}

/// Arguments of `bitt convert-mediapipe`.
#[derive(Debug, clap::Args)]
pub struct ConvertMediapipeArgs {
    /// The unpacked `mediapipe==0.10.21` wheel: `pip download --no-deps mediapipe==0.10.21`
    /// (any platform's wheel), then `unzip mediapipe-0.10.21-*.whl -d DIR`. Its
    /// `mediapipe/modules/palm_detection/palm_detection_full.tflite` and
    /// `mediapipe/modules/hand_landmark/hand_landmark_full.tflite` are read.
    #[arg(long)]
    pub wheel_dir: PathBuf,
    /// The weights file to write (the one built into bitt is
    /// `crates/bitt-detect/assets/mediapipe_hands.safetensors`; rebuild bitt after
    /// replacing it).
    #[arg(long)]
    pub out: PathBuf,
}

/// `bitt detect-hands`.
pub fn run(args: &DetectHandsArgs) -> Result<()> {
    let device = args.device.device()?;
    let done = bitt::detect::detect_hands_into(&args.image, &args.out, &device)?;
    for line in done.lines(&args.out) {
        println!("{line}");
    }
    if let Some(w) = &done.warning {
        eprintln!("warning: {w}");
    }
    Ok(())
}

/// `bitt convert-mediapipe`.
pub fn convert(args: &ConvertMediapipeArgs) -> Result<()> {
    let bytes = bitt::detect::convert_mediapipe(&args.wheel_dir, &args.out)?;
    println!("wrote {} ({bytes} bytes)", args.out.display());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use bitt_tests::real_fixture::scratch;

    type Cli = crate::test_args::Parsed<DetectHandsArgs>;

    type ConvertCli = crate::test_args::Parsed<ConvertMediapipeArgs>;

    #[test]
    fn arguments_parse() {
        let a = Cli::try_parse_from(["bitt", "--image", "p.jpg"])
            .unwrap()
            .args;
        assert_eq!(a.out, PathBuf::from("runs/detect-hands"));
        assert_eq!(a.device, DeviceName::Flex);
        let a = Cli::try_parse_from([
            "bitt", "--image", "p.jpg", "--out", "o", "--device", "ndarray",
        ])
        .unwrap()
        .args;
        assert_eq!((a.out, a.device), (PathBuf::from("o"), DeviceName::Ndarray));
        assert!(
            Cli::try_parse_from(["bitt"]).is_err(),
            "--image is required"
        );
        assert!(Cli::try_parse_from(["bitt", "--image", "p.jpg", "--keypoints", "k"]).is_err());
        let c = ConvertCli::try_parse_from(["bitt", "--wheel-dir", "w", "--out", "x.safetensors"])
            .unwrap()
            .args;
        assert_eq!(c.wheel_dir, PathBuf::from("w"));
        assert!(ConvertCli::try_parse_from(["bitt", "--wheel-dir", "w"]).is_err());
    }

    /// A folder of the user's is refused before anything is read; a file that is not an
    /// image, a missing photo and a wheel folder without the models are errors naming them;
    /// nothing is written.
    #[test]
    fn bad_inputs_write_nothing() {
        let dir = scratch("cli-detect-bad");
        let out = dir.join("out");
        let attempt = |image: &std::path::Path, out: &std::path::Path| {
            let a = Cli::try_parse_from([
                "bitt",
                "--image",
                image.to_str().unwrap(),
                "--out",
                out.to_str().unwrap(),
            ])
            .unwrap()
            .args;
            format!("{:#}", run(&a).unwrap_err())
        };
        let text = dir.join("notes.jpg");
        std::fs::write(&text, "not an image").unwrap();
        let e = attempt(&text, &out);
        assert!(e.contains("notes.jpg"), "{e}");
        let e = attempt(&dir.join("missing.png"), &out);
        assert!(e.contains("missing.png"), "{e}");
        assert!(!out.exists(), "a failed detection wrote {}", out.display());
        let foreign = dir.join("foreign");
        std::fs::create_dir_all(&foreign).unwrap();
        std::fs::write(foreign.join("mine.txt"), "mine").unwrap();
        let e = attempt(&text, &foreign);
        assert!(e.contains("not a detect-hands output"), "{e}");
        assert_eq!(
            std::fs::read_dir(&foreign).unwrap().count(),
            1,
            "the user's folder was written to"
        );
        let weights = dir.join("w.safetensors");
        let c = ConvertCli::try_parse_from([
            "bitt",
            "--wheel-dir",
            dir.join("wheel").to_str().unwrap(),
            "--out",
            weights.to_str().unwrap(),
        ])
        .unwrap()
        .args;
        let e = format!("{:#}", convert(&c).unwrap_err());
        assert!(e.contains("palm_detection_full.tflite"), "{e}");
        assert!(!weights.exists());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
