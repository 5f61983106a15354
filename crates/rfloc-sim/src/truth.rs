//! `truth.csv`: the true trajectory of a run, header `t,x,y,theta` (seconds, metres,
//! radians), one pose per line.

use std::fmt::Write as _;
use std::path::Path;

use rfloc_pose::Pose2;

use crate::error::SimError;
use crate::metrics::TimedPose;

/// The header line.
pub const HEADER: &str = "t,x,y,theta";

/// Renders poses as `truth.csv` text (full `f64` precision, so reading it back is exact).
#[must_use]
pub fn to_csv(poses: &[TimedPose]) -> String {
    let mut s = String::with_capacity(32 * (poses.len() + 1));
    s.push_str(HEADER);
    s.push('\n');
    for p in poses {
        let _ = writeln!(s, "{},{},{},{}", p.t, p.pose.x, p.pose.y, p.pose.theta);
    }
    s
}

/// Writes `truth.csv`.
pub fn write(path: &Path, poses: &[TimedPose]) -> Result<(), SimError> {
    std::fs::write(path, to_csv(poses)).map_err(|source| SimError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Parses `truth.csv` text; errors name the line. Blank lines are skipped.
pub fn parse(text: &str, path: &Path) -> Result<Vec<TimedPose>, SimError> {
    let err = |line: usize, message: String| SimError::Csv {
        path: path.to_path_buf(),
        line,
        message,
    };
    let mut lines = text.lines().enumerate();
    match lines.next() {
        Some((_, h)) if h.trim() == HEADER => {}
        Some((_, h)) => return Err(err(1, format!("expected header `{HEADER}`, found `{h}`"))),
        None => return Err(err(1, "empty file".to_string())),
    }
    let mut out = Vec::new();
    for (i, l) in lines {
        if l.trim().is_empty() {
            continue;
        }
        let fields: Vec<&str> = l.split(',').map(str::trim).collect();
        let [t, x, y, th] = fields.as_slice() else {
            return Err(err(
                i + 1,
                format!("expected 4 fields, found {}: `{l}`", fields.len()),
            ));
        };
        let num = |s: &str, name: &str| -> Result<f64, SimError> {
            s.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| err(i + 1, format!("`{name}` is not a finite number: `{s}`")))
        };
        let t = num(t, "t")?;
        if let Some(last) = out.last().map(|p: &TimedPose| p.t) {
            if t < last {
                return Err(err(i + 1, format!("time goes backwards ({t} < {last})")));
            }
        }
        out.push(TimedPose::new(
            t,
            Pose2 {
                x: num(x, "x")?,
                y: num(y, "y")?,
                theta: num(th, "theta")?,
            },
        ));
    }
    Ok(out)
}

/// Reads `truth.csv`.
pub fn read(path: &Path) -> Result<Vec<TimedPose>, SimError> {
    let text = std::fs::read_to_string(path).map_err(|source| SimError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse(&text, path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_is_exact() {
        let poses: Vec<TimedPose> = (0..50)
            .map(|i| {
                TimedPose::new(
                    f64::from(i) * 0.1,
                    Pose2::new(f64::from(i).sin(), 1.0 / 3.0, f64::from(i) * 0.7),
                )
            })
            .collect();
        let text = to_csv(&poses);
        assert!(text.starts_with("t,x,y,theta\n"));
        assert_eq!(parse(&text, Path::new("t.csv")).unwrap(), poses);
    }

    #[test]
    fn file_round_trip() {
        let dir = std::env::temp_dir().join(format!("rfloc-sim-truth-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("truth.csv");
        let poses = vec![TimedPose::new(0.0, Pose2::new(1.0, 2.0, 0.5))];
        write(&p, &poses).unwrap();
        assert_eq!(read(&p).unwrap(), poses);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn errors_name_the_line() {
        let e = parse("t,x,y,theta\n0,0,0,0\n0.1,0,zz,0\n", Path::new("t.csv")).unwrap_err();
        assert_eq!(e.to_string(), "t.csv:3: `y` is not a finite number: `zz`");
        let e = parse("t,x,y\n", Path::new("t.csv")).unwrap_err();
        assert!(e.to_string().starts_with("t.csv:1: expected header"));
        let e = parse("t,x,y,theta\n1,0,0,0\n0,0,0,0\n", Path::new("t.csv")).unwrap_err();
        assert!(e.to_string().contains(":3: time goes backwards"));
        let e = parse("t,x,y,theta\n1,0,0\n", Path::new("t.csv")).unwrap_err();
        assert!(e.to_string().contains(":2: expected 4 fields"));
    }
}
