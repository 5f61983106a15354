//! The world: area, walls, obstacles, UHF tags, the HF floor grid, XBee beacons and the RF
//! emitter. [`WorldSpec`] is the TOML form (see `docs/simulator.md`); [`World`] is the
//! resolved form the models use (random placements drawn, UIDs assigned, wall segments listed).

use std::path::Path;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::error::{find_key_line, from_toml, SimError};
use crate::geometry::{Point, Polygon, Segment};

/// TOML form of a world file (also used inline as `[world]` in a scenario).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WorldSpec {
    /// Free-text name shown in reports.
    #[serde(default)]
    pub name: String,
    /// The rectangular operating area.
    pub area: AreaSpec,
    /// Open polylines (walls, shelf fronts).
    #[serde(default)]
    pub walls: Vec<PolylineSpec>,
    /// Closed polygons (boxes, shelves); their inside is not drivable.
    #[serde(default)]
    pub obstacles: Vec<PolylineSpec>,
    /// Passive UHF tags for the snapshot pipeline.
    #[serde(default)]
    pub uhf_tags: Option<UhfTagsSpec>,
    /// HF (ISO 15693) floor tag grid.
    #[serde(default)]
    pub hf_grid: Option<HfGridSpec>,
    /// XBee router beacons.
    #[serde(default)]
    pub xbee_beacons: Vec<BeaconSpec>,
    /// The single RF emitter carried by the target.
    #[serde(default)]
    pub emitter: Option<EmitterSpec>,
}

/// `[area]`: axis-aligned bounds in metres.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AreaSpec {
    pub min: [f64; 2],
    pub max: [f64; 2],
    /// Add the four sides of the area as walls (default true).
    #[serde(default = "default_true")]
    pub boundary_walls: bool,
}

fn default_true() -> bool {
    true
}

/// A list of vertices `[[x, y], …]` in metres.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PolylineSpec {
    pub points: Vec<[f64; 2]>,
}

/// Longest side of a world's area, metres (a 10 km floor; simulators and planners grid it).
pub const MAX_SIDE_M: f64 = 10_000.0;
/// Farthest a world's corner may lie from the origin, metres.
pub const MAX_COORDINATE_M: f64 = 1.0e6;

/// `[uhf_tags]`: explicit tags and/or a seeded random placement.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UhfTagsSpec {
    #[serde(default)]
    pub tags: Vec<UhfTagSpec>,
    #[serde(default)]
    pub random: Option<RandomTagsSpec>,
}

/// One explicit UHF tag.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UhfTagSpec {
    /// EPC as hexadecimal text.
    pub epc: String,
    pub x: f64,
    pub y: f64,
    /// Direction of the tag's normal, degrees CCW from +x.
    #[serde(default)]
    pub normal_deg: f64,
}

/// `random = { count, seed, epc_prefix }`: uniform positions in the area outside obstacles,
/// uniform normals; EPC = prefix followed by the index as hex, 24 hex digits in total.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RandomTagsSpec {
    pub count: usize,
    pub seed: u64,
    #[serde(default = "default_epc_prefix")]
    pub epc_prefix: String,
}

fn default_epc_prefix() -> String {
    "E200".to_string()
}

/// `[hf_grid]`: a `rows × cols` grid of HF tags on the floor.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HfGridSpec {
    /// Position of the tag at row 0, column 0 (metres).
    pub origin: [f64; 2],
    /// Spacing between neighbouring tags (metres; seed 002 uses 0.10).
    pub pitch: f64,
    pub rows: usize,
    pub cols: usize,
    /// UID of tag (0,0) as hex; tag `(r, c)` gets `uid_base + r * cols + c` (row-major, x
    /// fastest) unless `uids` is given.
    #[serde(default = "default_uid_base")]
    pub uid_base: String,
    /// Explicit UIDs (hex), row-major with x fastest; length must be `rows * cols`.
    #[serde(default)]
    pub uids: Vec<String>,
}

fn default_uid_base() -> String {
    "E004020000000000".to_string()
}

/// `[[xbee_beacons]]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BeaconSpec {
    pub x: f64,
    pub y: f64,
    /// 64-bit serial number as 16 hex digits.
    pub address: String,
    /// Node identifier, `beacon#` in seed 003.
    pub ni: String,
}

/// `[emitter]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EmitterSpec {
    pub x: f64,
    pub y: f64,
    /// Transmit power in dBm (seed 001 quotes detection beyond 50 m at 0 dBm).
    #[serde(default)]
    pub power_dbm: f64,
}

/// A resolved passive UHF tag.
#[derive(Debug, Clone, PartialEq)]
pub struct UhfTag {
    pub epc: String,
    pub position: Point,
    /// Normal direction, radians.
    pub normal: f64,
}

/// A resolved HF floor tag.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HfTag {
    pub uid: u64,
    pub position: Point,
    pub row: usize,
    pub col: usize,
}

/// A resolved XBee beacon.
#[derive(Debug, Clone, PartialEq)]
pub struct XbeeBeacon {
    pub address: u64,
    pub ni: String,
    pub position: Point,
}

/// A resolved RF emitter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Emitter {
    pub position: Point,
    pub power_dbm: f64,
}

/// The resolved world used by kinematics and sensor models.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct World {
    pub name: String,
    pub area_min: Point,
    pub area_max: Point,
    /// Every blocking segment: walls, obstacle edges and (optionally) the area boundary.
    pub walls: Vec<Segment>,
    /// Closed obstacles (their interior is blocked).
    pub obstacles: Vec<Polygon>,
    pub uhf_tags: Vec<UhfTag>,
    pub hf_tags: Vec<HfTag>,
    /// HF grid pitch when a grid is present.
    pub hf_pitch: Option<f64>,
    pub beacons: Vec<XbeeBeacon>,
    pub emitter: Option<Emitter>,
}

fn invalid(path: &Path, text: &str, key: &str, message: impl Into<String>) -> SimError {
    SimError::Invalid {
        path: path.to_path_buf(),
        line: find_key_line(text, key),
        key: key.to_string(),
        message: message.into(),
    }
}

fn parse_hex_u64(s: &str) -> Option<u64> {
    let s = s.trim();
    let s = s
        .strip_prefix("0x")
        .or_else(|| s.strip_prefix("0X"))
        .unwrap_or(s);
    if s.is_empty() || s.len() > 16 {
        return None;
    }
    u64::from_str_radix(s, 16).ok()
}

fn pt(p: [f64; 2]) -> Point {
    Point::new(p[0], p[1])
}

impl World {
    /// Reads and resolves a world file.
    pub fn load(path: &Path) -> Result<World, SimError> {
        let text = std::fs::read_to_string(path).map_err(|source| SimError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        World::from_toml_str(&text, path)
    }

    /// Parses and resolves world TOML; `path` is used in error messages only.
    pub fn from_toml_str(text: &str, path: &Path) -> Result<World, SimError> {
        let spec: WorldSpec = toml::from_str(text).map_err(|e| from_toml(path, text, &e))?;
        World::resolve(&spec, text, path)
    }

    /// Validates `spec` and resolves it. `text` is the TOML it came from (used to find the
    /// line of an invalid key; pass "" when there is none).
    pub fn resolve(spec: &WorldSpec, text: &str, path: &Path) -> Result<World, SimError> {
        let all_finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        let (min, max) = (spec.area.min, spec.area.max);
        if !all_finite(&[min[0], min[1], max[0], max[1]]) || max[0] <= min[0] || max[1] <= min[1] {
            return Err(invalid(
                path,
                text,
                "area",
                "max must be finite and greater than min",
            ));
        }
        // The largest floor a trial models (the simulators and planners grid it).
        let within = |v: f64| v.abs() <= MAX_COORDINATE_M;
        if max[0] - min[0] > MAX_SIDE_M
            || max[1] - min[1] > MAX_SIDE_M
            || !min.iter().chain(&max).all(|&v| within(v))
        {
            return Err(invalid(
                path,
                text,
                "area",
                format!(
                    "each side at most {MAX_SIDE_M} m, corners within {MAX_COORDINATE_M} m of the origin"
                ),
            ));
        }
        let mut world = World {
            name: spec.name.clone(),
            area_min: pt(min),
            area_max: pt(max),
            ..World::default()
        };
        if spec.area.boundary_walls {
            let c = [
                Point::new(min[0], min[1]),
                Point::new(max[0], min[1]),
                Point::new(max[0], max[1]),
                Point::new(min[0], max[1]),
            ];
            world.walls.extend(
                Polygon {
                    vertices: c.to_vec(),
                }
                .edges(),
            );
        }
        for w in &spec.walls {
            if w.points.len() < 2 || !w.points.iter().all(|p| all_finite(p)) {
                return Err(invalid(
                    path,
                    text,
                    "walls",
                    "a wall needs at least 2 finite points",
                ));
            }
            world
                .walls
                .extend(w.points.windows(2).filter_map(|p| match p {
                    [a, b] => Some(Segment::new(pt(*a), pt(*b))),
                    _ => None,
                }));
        }
        for o in &spec.obstacles {
            if o.points.len() < 3 || !o.points.iter().all(|p| all_finite(p)) {
                return Err(invalid(
                    path,
                    text,
                    "obstacles",
                    "an obstacle needs at least 3 finite points",
                ));
            }
            let poly = Polygon {
                vertices: o.points.iter().map(|p| pt(*p)).collect(),
            };
            world.walls.extend(poly.edges());
            world.obstacles.push(poly);
        }
        if let Some(u) = &spec.uhf_tags {
            for t in &u.tags {
                if parse_hex_u128_ok(&t.epc).is_none() {
                    return Err(invalid(
                        path,
                        text,
                        "uhf_tags.tags.epc",
                        format!("`{}` is not hex", t.epc),
                    ));
                }
                world.uhf_tags.push(UhfTag {
                    epc: t.epc.to_uppercase(),
                    position: Point::new(t.x, t.y),
                    normal: t.normal_deg.to_radians(),
                });
            }
            if let Some(r) = &u.random {
                if r.count > 1_000_000 {
                    return Err(invalid(
                        path,
                        text,
                        "uhf_tags.random.count",
                        "at most 1000000 tags",
                    ));
                }
                if r.epc_prefix.len() > 8 || parse_hex_u128_ok(&r.epc_prefix).is_none() {
                    return Err(invalid(
                        path,
                        text,
                        "uhf_tags.random.epc_prefix",
                        "1 to 8 hex digits",
                    ));
                }
                world.place_random_tags(r);
                if world.uhf_tags.len() < r.count {
                    return Err(invalid(
                        path,
                        text,
                        "uhf_tags.random",
                        "obstacles leave no room for the tags",
                    ));
                }
            }
        }
        if let Some(g) = &spec.hf_grid {
            world.resolve_hf_grid(g, text, path)?;
        }
        let inside = |x: f64, y: f64| {
            x.is_finite()
                && y.is_finite()
                && x >= min[0]
                && x <= max[0]
                && y >= min[1]
                && y <= max[1]
        };
        let value_line = |value: &str, key: &str| {
            let l = find_value_line(text, value);
            if l > 0 {
                l
            } else {
                find_key_line(text, key)
            }
        };
        for t in &world.uhf_tags {
            if !inside(t.position.x, t.position.y) {
                return Err(SimError::Invalid {
                    path: path.to_path_buf(),
                    line: value_line(&t.epc, "uhf_tags.tags"),
                    key: "uhf_tags.tags".to_string(),
                    message: format!(
                        "tag {} at ({}, {}) is outside the area",
                        t.epc, t.position.x, t.position.y
                    ),
                });
            }
        }
        if let Some(t) = world
            .hf_tags
            .iter()
            .find(|t| !inside(t.position.x, t.position.y))
        {
            return Err(invalid(
                path,
                text,
                "hf_grid",
                format!(
                    "tag (row {}, column {}) at ({:.3}, {:.3}) is outside the area",
                    t.row, t.col, t.position.x, t.position.y
                ),
            ));
        }
        for b in &spec.xbee_beacons {
            let address = parse_hex_u64(&b.address).ok_or_else(|| {
                invalid(
                    path,
                    text,
                    "xbee_beacons.address",
                    format!("`{}` is not a 64-bit hex address", b.address),
                )
            })?;
            let located = |message: String| SimError::Invalid {
                path: path.to_path_buf(),
                line: value_line(&b.address, "xbee_beacons.address"),
                key: "xbee_beacons.address".to_string(),
                message,
            };
            if world.beacons.iter().any(|o| o.address == address) {
                let earlier = spec
                    .xbee_beacons
                    .iter()
                    .take_while(|o| !std::ptr::eq(*o, b))
                    .filter(|o| o.address == b.address)
                    .count();
                let line = find_value_line_nth(text, &b.address, earlier);
                return Err(SimError::Invalid {
                    path: path.to_path_buf(),
                    line: if line > 0 {
                        line
                    } else {
                        find_key_line(text, "xbee_beacons.address")
                    },
                    key: "xbee_beacons.address".to_string(),
                    message: format!(
                        "`{}` is the address of an earlier beacon; every beacon needs its own",
                        b.address
                    ),
                });
            }
            if !inside(b.x, b.y) {
                return Err(located(format!(
                    "beacon `{}` at ({}, {}) is outside the area",
                    b.address, b.x, b.y
                )));
            }
            world.beacons.push(XbeeBeacon {
                address,
                ni: b.ni.clone(),
                position: Point::new(b.x, b.y),
            });
        }
        if let Some(e) = &spec.emitter {
            if !inside(e.x, e.y) {
                return Err(invalid(
                    path,
                    text,
                    "emitter",
                    format!("({}, {}) is outside the area", e.x, e.y),
                ));
            }
            if world.inside_obstacle(&Point::new(e.x, e.y)) {
                return Err(invalid(
                    path,
                    text,
                    "emitter",
                    format!("({}, {}) is inside an obstacle", e.x, e.y),
                ));
            }
            world.emitter = Some(Emitter {
                position: Point::new(e.x, e.y),
                power_dbm: e.power_dbm,
            });
        }
        Ok(world)
    }

    fn place_random_tags(&mut self, r: &RandomTagsSpec) {
        let mut rng = ChaCha8Rng::seed_from_u64(r.seed);
        let width = 24usize.saturating_sub(r.epc_prefix.len());
        let mut placed = 0usize;
        let mut attempts = 0usize;
        while placed < r.count && attempts < r.count.saturating_mul(100).max(100) {
            attempts += 1;
            let x = rng.random_range(self.area_min.x..self.area_max.x);
            let y = rng.random_range(self.area_min.y..self.area_max.y);
            let normal = rng.random_range(-std::f64::consts::PI..std::f64::consts::PI);
            let p = Point::new(x, y);
            if self.inside_obstacle(&p) {
                continue;
            }
            self.uhf_tags.push(UhfTag {
                epc: format!(
                    "{}{:0width$X}",
                    r.epc_prefix.to_uppercase(),
                    placed,
                    width = width
                ),
                position: p,
                normal,
            });
            placed += 1;
        }
    }

    fn resolve_hf_grid(&mut self, g: &HfGridSpec, text: &str, path: &Path) -> Result<(), SimError> {
        // HF tags a reader tells apart (its field is a few centimetres across), on a floor
        // the area can hold.
        if !(g.pitch.is_finite() && (0.01..=100.0).contains(&g.pitch)) {
            return Err(invalid(
                path,
                text,
                "hf_grid.pitch",
                "must be from 0.01 to 100 m",
            ));
        }
        let n = g
            .rows
            .checked_mul(g.cols)
            .filter(|n| *n <= 1_000_000)
            .ok_or_else(|| {
                invalid(
                    path,
                    text,
                    "hf_grid.rows",
                    "rows * cols must be at most 1000000",
                )
            })?;
        let base = parse_hex_u64(&g.uid_base)
            .ok_or_else(|| invalid(path, text, "hf_grid.uid_base", "not a 64-bit hex UID"))?;
        if !g.uids.is_empty() && g.uids.len() != n {
            return Err(invalid(
                path,
                text,
                "hf_grid.uids",
                format!("has {} entries, rows * cols = {n}", g.uids.len()),
            ));
        }
        for r in 0..g.rows {
            for c in 0..g.cols {
                let idx = r * g.cols + c;
                let uid = match g.uids.get(idx) {
                    Some(s) => parse_hex_u64(s).ok_or_else(|| {
                        invalid(
                            path,
                            text,
                            "hf_grid.uids",
                            format!("`{s}` is not a 64-bit hex UID"),
                        )
                    })?,
                    None => base.wrapping_add(idx as u64),
                };
                self.hf_tags.push(HfTag {
                    uid,
                    position: Point::new(
                        g.origin[0] + c as f64 * g.pitch,
                        g.origin[1] + r as f64 * g.pitch,
                    ),
                    row: r,
                    col: c,
                });
            }
        }
        self.hf_pitch = Some(g.pitch);
        Ok(())
    }

    /// True when `p` lies inside a closed obstacle.
    #[must_use]
    pub fn inside_obstacle(&self, p: &Point) -> bool {
        self.obstacles.iter().any(|o| o.contains(p))
    }

    /// True when a disk of `radius` at `centre` touches a wall or lies in an obstacle.
    #[must_use]
    pub fn disk_collides(&self, centre: &Point, radius: f64) -> bool {
        self.inside_obstacle(centre)
            || self
                .walls
                .iter()
                .any(|w| w.distance_to_point(centre) < radius)
    }

    /// Number of wall segments crossed by the straight line from `a` to `b`.
    #[must_use]
    pub fn walls_crossed(&self, a: &Point, b: &Point) -> usize {
        let s = Segment::new(*a, *b);
        self.walls.iter().filter(|w| w.intersects(&s)).count()
    }

    /// Distance along a ray to the nearest wall, if any.
    #[must_use]
    pub fn ray_cast(&self, origin: &Point, angle: f64) -> Option<f64> {
        self.walls
            .iter()
            .filter_map(|w| w.ray_hit(origin, angle))
            .fold(None, |best: Option<f64>, d| {
                Some(best.map_or(d, |b| b.min(d)))
            })
    }
}

/// 1-based line on which the quoted string `value` first appears, 0 when absent.
fn find_value_line(text: &str, value: &str) -> usize {
    find_value_line_nth(text, value, 0)
}

/// 1-based line of the `n`-th (from 0) appearance of the quoted string `value`, 0 when absent.
fn find_value_line_nth(text: &str, value: &str, n: usize) -> usize {
    let quoted = format!("\"{value}\"");
    text.lines()
        .enumerate()
        .filter(|(_, l)| l.contains(&quoted))
        .nth(n)
        .map_or(0, |(i, _)| i + 1)
}

fn parse_hex_u128_ok(s: &str) -> Option<()> {
    let ok = !s.is_empty() && s.len() <= 32 && s.chars().all(|c| c.is_ascii_hexdigit());
    ok.then_some(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const SMALL: &str = r#"
name = "t"
[area]
min = [0.0, 0.0]
max = [5.0, 5.0]

[[obstacles]]
points = [[1.0, 1.0], [2.0, 1.0], [2.0, 2.0], [1.0, 2.0]]

[uhf_tags]
random = { count = 50, seed = 7 }

[hf_grid]
origin = [0.0, 0.0]
pitch = 0.1
rows = 3
cols = 3

[[xbee_beacons]]
x = 0.0
y = 3.5
address = "0013A20040000001"
ni = "beacon1"
"#;

    #[test]
    fn resolves_walls_tags_grid_beacons() {
        let w = World::from_toml_str(SMALL, Path::new("small.toml")).unwrap();
        assert_eq!(w.walls.len(), 8);
        assert_eq!(w.uhf_tags.len(), 50);
        assert!(w.uhf_tags.iter().all(|t| !w.inside_obstacle(&t.position)));
        assert!(w.uhf_tags.iter().all(|t| t.epc.len() == 24));
        assert_eq!(w.hf_tags.len(), 9);
        assert_eq!(w.hf_tags[4].uid, 0xE004_0200_0000_0004);
        assert!((w.hf_tags[5].position.x - 0.2).abs() < 1e-12);
        assert_eq!(w.beacons[0].address, 0x0013_A200_4000_0001);
        // Integers are accepted where floats are expected.
        let ints =
            World::from_toml_str("[area]\nmin = [0, 0]\nmax = [5, 5]\n", Path::new("i")).unwrap();
        assert_eq!(ints.area_max, Point::new(5.0, 5.0));
    }

    #[test]
    fn random_placement_is_deterministic_per_seed() {
        let a = World::from_toml_str(SMALL, Path::new("a")).unwrap();
        let b = World::from_toml_str(SMALL, Path::new("b")).unwrap();
        assert_eq!(a.uhf_tags, b.uhf_tags);
        let c =
            World::from_toml_str(&SMALL.replace("seed = 7", "seed = 8"), Path::new("c")).unwrap();
        assert_ne!(a.uhf_tags, c.uhf_tags);
    }

    /// A pitch no reader tells apart (all tags at one point) and a floor beyond 10 km are
    /// errors at their lines.
    #[test]
    fn an_hf_pitch_or_an_area_out_of_range_is_rejected() {
        for pitch in ["1e-320", "0.001", "-0.1", "nan", "1000.0"] {
            let bad = SMALL.replace("pitch = 0.1", &format!("pitch = {pitch}"));
            let msg = World::from_toml_str(&bad, Path::new("w.toml"))
                .unwrap_err()
                .to_string();
            assert!(msg.starts_with("w.toml:15:"), "{pitch}: {msg}");
            assert!(msg.contains("hf_grid.pitch"), "{pitch}: {msg}");
        }
        let far = SMALL.replacen("max = [", "max = [20000.0, 1.0] # was [", 1);
        assert!(World::from_toml_str(&far, Path::new("w.toml")).is_err());
    }

    #[test]
    fn unknown_key_error_names_file_line_and_key() {
        let bad = SMALL.replace("pitch = 0.1", "pitch = 0.1\nspacing = 0.1");
        let e = World::from_toml_str(&bad, Path::new("bad.toml")).unwrap_err();
        let msg = e.to_string();
        assert!(msg.starts_with("bad.toml:16:1:"), "{msg}");
        assert!(msg.contains("spacing"), "{msg}");
    }

    #[test]
    fn wrong_type_error_names_line_and_key() {
        let bad = SMALL.replace("rows = 3", "rows = \"three\"");
        match World::from_toml_str(&bad, Path::new("bad.toml")).unwrap_err() {
            SimError::Toml { line, key, .. } => {
                assert_eq!(line, 16);
                assert_eq!(key, "rows");
            }
            other => panic!("unexpected {other}"),
        }
    }

    #[test]
    fn invalid_value_error_names_key_and_line() {
        let bad = SMALL.replace("address = \"0013A20040000001\"", "address = \"xyz\"");
        match World::from_toml_str(&bad, Path::new("bad.toml")).unwrap_err() {
            SimError::Invalid { line, key, .. } => {
                assert_eq!(key, "xbee_beacons.address");
                assert_eq!(line, 22);
            }
            other => panic!("unexpected {other}"),
        }
    }

    #[test]
    fn disk_collision_against_wall_and_obstacle() {
        let w = World::from_toml_str(SMALL, Path::new("small.toml")).unwrap();
        assert!(w.disk_collides(&Point::new(0.1, 2.5), 0.2));
        assert!(w.disk_collides(&Point::new(1.5, 1.5), 0.1));
        assert!(!w.disk_collides(&Point::new(3.5, 3.5), 0.2));
        assert_eq!(
            w.walls_crossed(&Point::new(0.5, 1.5), &Point::new(3.0, 1.5)),
            2
        );
    }
}
