//! `truth.csv`: the true trajectory of a run, header `t,x,y,theta` (seconds, metres,
//! radians), one pose per line. Written and read with the `csv` crate.

use std::path::Path;

use rfloc_pose::Pose2;

use crate::error::SimError;
use crate::metrics::TimedPose;

/// The header line.
pub const HEADER: &str = "t,x,y,theta";

fn csv_error(path: &Path, line: usize, e: &csv::Error) -> SimError {
    SimError::Csv {
        path: path.to_path_buf(),
        line,
        message: e.to_string(),
    }
}

/// 1-based line of the record that starts at byte `byte` of `text` (the reader's own line
/// count skips blank lines, and its record positions start at the blank lines before a record).
fn line_of(text: &str, byte: u64) -> usize {
    let mut end = usize::try_from(byte).unwrap_or(usize::MAX).min(text.len());
    while matches!(text.as_bytes().get(end), Some(b'\n' | b'\r')) {
        end += 1;
    }
    text.as_bytes()
        .get(..end)
        .map_or(0, |b| b.iter().filter(|c| **c == b'\n').count())
        + 1
}

/// Renders poses as `truth.csv` text (each number in Rust's shortest exact form, so reading
/// it back is exact).
#[must_use]
pub fn to_csv(poses: &[TimedPose]) -> String {
    let mut w = csv::WriterBuilder::new()
        .terminator(csv::Terminator::Any(b'\n'))
        .from_writer(Vec::with_capacity(32 * (poses.len() + 1)));
    // Writing into memory cannot fail.
    let _ = w.write_record(HEADER.split(','));
    for p in poses {
        let _ = w.write_record([
            p.t.to_string(),
            p.pose.x.to_string(),
            p.pose.y.to_string(),
            p.pose.theta.to_string(),
        ]);
    }
    let bytes = w.into_inner().unwrap_or_default();
    String::from_utf8(bytes).unwrap_or_default()
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
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .trim(csv::Trim::All)
        .from_reader(text.as_bytes());
    let mut records = reader.records();
    match records.next() {
        Some(Ok(h)) if h.iter().eq(HEADER.split(',')) => {}
        Some(Ok(h)) => {
            let found: Vec<&str> = h.iter().collect();
            return Err(err(
                1,
                format!("expected header `{HEADER}`, found `{}`", found.join(",")),
            ));
        }
        Some(Err(e)) => return Err(csv_error(path, 1, &e)),
        None => return Err(err(1, "empty file".to_string())),
    }
    let mut out = Vec::new();
    for record in records {
        let record = record.map_err(|e| {
            let line = e.position().map_or(0, |p| line_of(text, p.byte()));
            csv_error(path, line, &e)
        })?;
        let line = record.position().map_or(0, |p| line_of(text, p.byte()));
        if record.iter().all(str::is_empty) {
            continue;
        }
        let fields: Vec<&str> = record.iter().collect();
        let [t, x, y, th] = fields.as_slice() else {
            return Err(err(
                line,
                format!(
                    "expected 4 fields, found {}: `{}`",
                    fields.len(),
                    fields.join(",")
                ),
            ));
        };
        let num = |s: &str, name: &str| -> Result<f64, SimError> {
            s.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| err(line, format!("`{name}` is not a finite number: `{s}`")))
        };
        let t = num(t, "t")?;
        if let Some(last) = out.last().map(|p: &TimedPose| p.t) {
            if t < last {
                return Err(err(line, format!("time goes backwards ({t} < {last})")));
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
        // Blank lines are skipped, and line numbers still count them.
        let e = parse("t,x,y,theta\n\n0,0,0,0\n\n0,0,q,0\n", Path::new("t.csv")).unwrap_err();
        assert!(e.to_string().starts_with("t.csv:5: `y`"), "{e}");
        assert_eq!(
            parse("t,x,y,theta\n\n0,1,2,3\n", Path::new("t.csv"))
                .unwrap()
                .len(),
            1
        );
    }
}
