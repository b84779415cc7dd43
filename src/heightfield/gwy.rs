//! Gwyddion native files (`.gwy`), read from the format's description in the Gwyddion user
//! guide. After the magic `GWYP` comes one serialised object, a `GwyContainer`. An object
//! is its type name (NUL-terminated), its data size (u32, little-endian, the bytes of the
//! components that follow) and its components; a component is a name (NUL-terminated), a
//! type byte and the value: `b` bool (1 byte), `c` char (1), `i` i32, `q` i64, `d` f64, `s`
//! NUL-terminated string, `o` object; upper case is an array (u32 count, then the items).
//!
//! The container holds image channels as `"/N/data"` → `GwyDataField` (`xres`, `yres`,
//! `xreal`, `yreal`, `xoff`, `yoff`, `si_unit_xy` and `si_unit_z` as `GwySIUnit` objects with
//! a `unitstr`, and `data`, an array of `xres·yres` doubles), with the title in
//! `"/N/data/title"`. Every length is checked against the bytes left before it is used, so a
//! truncated or lying file is an error, never a large allocation; arrays stay slices of the
//! file until the chosen channel is decoded.

use std::path::Path;

use super::scan::{check_declared_size, Channel, ChannelInfo};
use crate::{Error, Result};

/// The four bytes every `.gwy` file begins with.
pub const MAGIC: &[u8; 4] = b"GWYP";

/// Deepest object nesting accepted: a container holds data fields that hold units (depth
/// 3); graphs and selections go a little deeper. A crafted file must not recurse without end.
const MAX_DEPTH: usize = 32;

/// A parsed value. Arrays are kept as their raw bytes.
#[derive(Debug)]
enum Value<'a> {
    Int(i64),
    Double(f64),
    Str(&'a str),
    Object(Object<'a>),
    /// An array (or a scalar diffract does not use): its type byte, item count and bytes.
    Raw(u8, usize, &'a [u8]),
}

#[derive(Debug)]
struct Object<'a> {
    type_name: &'a str,
    components: Vec<(&'a str, Value<'a>)>,
}

impl<'a> Object<'a> {
    fn get(&self, name: &str) -> Option<&Value<'a>> {
        self.components
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, v)| v)
    }
    fn int(&self, name: &str) -> Option<i64> {
        match self.get(name)? {
            Value::Int(i) => Some(*i),
            _ => None,
        }
    }
    fn double(&self, name: &str) -> Option<f64> {
        match self.get(name)? {
            Value::Double(d) => Some(*d),
            _ => None,
        }
    }
    fn unit(&self, name: &str) -> String {
        match self.get(name) {
            Some(Value::Object(u)) => match u.get("unitstr") {
                Some(Value::Str(s)) => s.to_string(),
                _ => String::new(),
            },
            _ => String::new(),
        }
    }
}

/// A cursor over the file's bytes whose every read is bounds-checked.
struct Cursor<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl<'a> Cursor<'a> {
    fn take(&mut self, n: usize, what: &str) -> std::result::Result<&'a [u8], String> {
        let end = self.pos.checked_add(n).filter(|&e| e <= self.bytes.len());
        let Some(end) = end else {
            return Err(format!(
                "{what} at byte {} needs {n} bytes but only {} remain (truncated?)",
                self.pos,
                self.bytes.len() - self.pos
            ));
        };
        let s = &self.bytes[self.pos..end];
        self.pos = end;
        Ok(s)
    }
    fn u32(&mut self, what: &str) -> std::result::Result<u32, String> {
        let b = self.take(4, what)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }
    fn string(&mut self, what: &str) -> std::result::Result<&'a str, String> {
        let rest = &self.bytes[self.pos..];
        let len = rest.iter().position(|&b| b == 0).ok_or_else(|| {
            format!(
                "{what} at byte {} has no terminating NUL (truncated?)",
                self.pos
            )
        })?;
        let s = std::str::from_utf8(&rest[..len])
            .map_err(|_| format!("{what} at byte {} is not UTF-8", self.pos))?;
        self.pos += len + 1;
        Ok(s)
    }

    fn object(&mut self, depth: usize) -> std::result::Result<Object<'a>, String> {
        if depth > MAX_DEPTH {
            return Err(format!("objects nested deeper than {MAX_DEPTH}"));
        }
        let type_name = self.string("object type name")?;
        let size = self.u32("object size")? as usize;
        let body = self.take(size, &format!("object {type_name:?}"))?;
        let mut inner = Cursor {
            bytes: body,
            pos: 0,
        };
        let mut components = Vec::new();
        while inner.pos < body.len() {
            let name = inner.string("component name")?;
            let kind = inner.take(1, "component type")?[0];
            let value = inner
                .value(kind, depth)
                .map_err(|e| format!("{type_name}.{name}: {e}"))?;
            components.push((name, value));
        }
        Ok(Object {
            type_name,
            components,
        })
    }

    fn value(&mut self, kind: u8, depth: usize) -> std::result::Result<Value<'a>, String> {
        let fixed = |b: &[u8]| {
            let mut a = [0u8; 8];
            a[..b.len()].copy_from_slice(b);
            a
        };
        Ok(match kind {
            b'b' | b'c' => Value::Int(i64::from(self.take(1, "value")?[0])),
            b'i' => Value::Int(i64::from(i32::from_le_bytes(
                self.take(4, "i32")?.try_into().unwrap_or([0; 4]),
            ))),
            b'q' => Value::Int(i64::from_le_bytes(fixed(self.take(8, "i64")?))),
            b'd' => Value::Double(f64::from_le_bytes(fixed(self.take(8, "double")?))),
            b's' => Value::Str(self.string("string")?),
            b'o' => Value::Object(self.object(depth + 1)?),
            b'C' | b'I' | b'Q' | b'D' => {
                let n = self.u32("array length")? as usize;
                let item = match kind {
                    b'C' => 1,
                    b'I' => 4,
                    _ => 8,
                };
                let bytes = self.take(n.saturating_mul(item), "array")?;
                Value::Raw(kind, n, bytes)
            }
            b'S' => {
                let n = self.u32("array length")? as usize;
                let start = self.pos;
                for _ in 0..n {
                    self.string("string array item")?;
                }
                Value::Raw(kind, n, &self.bytes[start..self.pos])
            }
            b'O' => {
                let n = self.u32("array length")? as usize;
                // Each object takes at least 5 bytes: a count the bytes cannot hold is
                // refused at once instead of failing item by item.
                if n > (self.bytes.len() - self.pos) / 5 {
                    return Err(format!(
                        "object array of {n} items cannot fit the bytes left"
                    ));
                }
                // Parsed, so a broken one is an error; diffract reads none.
                let start = self.pos;
                for _ in 0..n {
                    self.object(depth + 1)?;
                }
                Value::Raw(kind, n, &self.bytes[start..self.pos])
            }
            other => return Err(format!("unknown component type {:?}", other as char)),
        })
    }
}

/// The image channels of a `.gwy` file: their descriptions (in channel-number order) and
/// where their data lie.
pub struct GwyFile {
    bytes: Vec<u8>,
}

impl GwyFile {
    /// Reads the file (bounded by [`super::scan::MAX_SCAN_BYTES`]).
    pub fn read(path: &Path) -> Result<Self> {
        let bytes = crate::fsutil::read_bounded(path, "scan file", super::scan::MAX_SCAN_BYTES)?;
        Ok(Self { bytes })
    }

    /// Wraps bytes already in memory.
    pub fn from_bytes(bytes: Vec<u8>) -> Self {
        Self { bytes }
    }

    /// The channels' descriptions, in channel-number order.
    pub fn channels(&self, path: &Path) -> Result<Vec<ChannelInfo>> {
        Ok(self.parse(path)?.into_iter().map(|f| f.info).collect())
    }

    /// Decodes channel `index` (an index into [`GwyFile::channels`]).
    pub fn channel(&self, path: &Path, index: usize) -> Result<Channel> {
        let mut all = self.parse(path)?;
        if index >= all.len() {
            return Err(Error::parse(path, format!("no channel {index}")));
        }
        let Found { info, data, .. } = all.swap_remove(index);
        let data = data
            .chunks_exact(8)
            .map(|b| f64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]))
            .collect();
        Ok(Channel { info, data })
    }

    /// Parses the tree and lists the channels with their data bytes (checked sizes).
    fn parse(&self, path: &Path) -> Result<Vec<Found<'_>>> {
        let bad = |msg: String| Error::parse(path, msg);
        if !self.bytes.starts_with(MAGIC) {
            let what = if self.bytes.starts_with(b"GWYO") {
                "an old-style GWYO file; open and save it again in Gwyddion 2"
            } else {
                "not a Gwyddion file (it must begin with GWYP)"
            };
            return Err(bad(what.into()));
        }
        let mut cur = Cursor {
            bytes: &self.bytes,
            pos: MAGIC.len(),
        };
        let root = cur.object(0).map_err(bad)?;
        if root.type_name != "GwyContainer" {
            return Err(bad(format!(
                "the top-level object is a {}, not a GwyContainer",
                root.type_name
            )));
        }
        let mut found = Vec::new();
        for (name, value) in &root.components {
            let Some(n) = channel_number(name) else {
                continue;
            };
            let Value::Object(field) = value else {
                continue;
            };
            if field.type_name != "GwyDataField" {
                continue;
            }
            let title = match root.get(&format!("{name}/title")) {
                Some(Value::Str(s)) => s.to_string(),
                _ => format!("channel {n}"),
            };
            let (info, data) = channel_of(path, field, title)?;
            // A mask of the same size (Gwyddion marks points with values ≥ 0.5).
            let mask = match root.get(&format!("/{n}/mask")) {
                Some(Value::Object(m)) if m.type_name == "GwyDataField" => {
                    match channel_of(path, m, "mask".into()) {
                        Ok((mi, bytes)) if (mi.nx, mi.ny) == (info.nx, info.ny) => Some(bytes),
                        _ => None,
                    }
                }
                _ => None,
            };
            found.push((n, Found { info, data, mask }));
        }
        found.sort_by_key(|(n, _)| *n);
        Ok(found.into_iter().map(|(_, c)| c).collect())
    }

    /// How many samples of channel `index` its mask marks (`None`: no mask). Gwyddion marks
    /// points it filled on import, or features a user selected; the data under a mask are
    /// finite either way.
    pub fn masked_points(&self, path: &Path, index: usize) -> Result<Option<usize>> {
        let all = self.parse(path)?;
        Ok(all.get(index).and_then(|f| f.mask).map(|bytes| {
            bytes
                .chunks_exact(8)
                .filter(|b| {
                    f64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]) >= 0.5
                })
                .count()
        }))
    }
}

/// A channel found in the container: its description, its data bytes and its mask's.
struct Found<'a> {
    info: ChannelInfo,
    data: &'a [u8],
    mask: Option<&'a [u8]>,
}

/// `"/12/data"` → 12.
fn channel_number(name: &str) -> Option<u64> {
    name.strip_prefix('/')?.strip_suffix("/data")?.parse().ok()
}

/// A `GwyDataField`'s description and data bytes, its declared size checked against them.
fn channel_of<'a>(
    path: &Path,
    field: &Object<'a>,
    title: String,
) -> Result<(ChannelInfo, &'a [u8])> {
    let bad = |msg: String| Error::parse(path, format!("channel \"{title}\": {msg}"));
    let (xres, yres) = match (field.int("xres"), field.int("yres")) {
        (Some(x), Some(y)) => (x, y),
        _ => return Err(bad("the data field lacks xres or yres".into())),
    };
    let data = match field.get("data") {
        Some(Value::Raw(b'D', n, bytes)) => {
            let (nx, ny) = check_declared_size(path, xres, yres, 8, bytes.len() as u64)?;
            if *n != nx * ny {
                return Err(bad(format!(
                    "{n} values for a {nx}×{ny} field (xres·yres = {})",
                    nx * ny
                )));
            }
            *bytes
        }
        _ => return Err(bad("the data field has no `data` array of doubles".into())),
    };
    let real = |name: &str| field.double(name).unwrap_or(1.0);
    Ok((
        ChannelInfo {
            title,
            nx: xres as usize,
            ny: yres as usize,
            x_real: real("xreal"),
            y_real: real("yreal"),
            xy_unit: field.unit("si_unit_xy"),
            z_unit: field.unit("si_unit_z"),
        },
        data,
    ))
}
