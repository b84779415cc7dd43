//! The one height-field loader every command goes through (`render`, `view`, `brdf`,
//! `eval-grating`, `profile`, `stability`, `heightfield --from-sample` and scene files): a
//! [`Source`] names the field (a file or `builtin:<kind>`), its scale overrides, the scan
//! channel, the levelling and the tiling, and [`Source::load`] does all of it in one order:
//!
//! 1. read: grey PNG and raw `.f32` ([`HeightField::load`]), `builtin:` fields, or a scan
//!    (`.gsf`, `.gwy`: the chosen channel with its units, [`super::scan`]);
//! 2. level ([`super::level`]): `plane,rows` by default for scans, nothing for images and
//!    `.f32` (they are taken as already processed); the report line and warnings go to the
//!    caller's [`Report`];
//! 3. report the seam's share of the spectrum (scans, or wherever `tile` is given) and tile
//!    ([`super::seam`]).
//!
//! The caches key on the loaded samples, so a different levelling or tiling is a different
//! cache entry without anything else to keep in step.

use std::path::Path;

use super::level::{level, Levelling};
use super::seam::{seam_share, tile, Tile};
use super::HeightField;
use crate::report::Report;
use crate::{Error, Result};

/// Where a height field comes from and what is done to it on the way in.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Source {
    /// A file path or `builtin:<kind>`.
    pub spec: String,
    /// Pixel size (µm); overrides the file and its sidecar.
    pub dh_um: Option<f64>,
    /// Images: height of grey level 1 (µm). Scans and built-in fields: the peak-to-valley
    /// height the field is scaled to. Overrides the sidecar.
    pub h_max_um: Option<f64>,
    /// Scans: the channel, by index or title (default: the first height channel).
    pub channel: Option<String>,
    /// Levelling steps (`plane,rows`, `poly:2`, `none`, …); `None`: the default for the
    /// format.
    pub level: Option<String>,
    /// How the field is made to tile; `None`: as it is.
    pub tile: Option<Tile>,
}

impl HeightField {
    /// Loads a grey PNG or raw `.f32` height field ([`HeightField::read_image`]: `dh_um` and
    /// `h_max_um` override the sidecar), or a Gwyddion scan (`.gsf`, `.gwy`) as stored: its
    /// first height channel, in its units, not levelled ([`Source`] levels and reports).
    pub fn load(path: &Path, dh_um: Option<f64>, h_max_um: Option<f64>) -> Result<HeightField> {
        if !is_scan(&path.to_string_lossy()) {
            return HeightField::read_image(path, dh_um, h_max_um);
        }
        let source = Source {
            dh_um,
            h_max_um,
            level: Some("none".into()),
            ..Source::new(path.to_string_lossy())
        };
        source.load(&crate::report::Collect::default())
    }

    /// `builtin:<kind>` (blazed, sinusoidal, elaphe, xenopeltis) is the default generated
    /// grating of that kind, the same field as the shipped `assets/<kind>.png` before
    /// quantisation; `dh_um` then resamples it at that pixel size and `h_max_um` rescales
    /// its peak-to-valley height. `builtin:elaphe-measured` is the shipped AFM crop
    /// (`assets/measured/`, embedded in the binary) and `builtin:elaphe-grown` that crop
    /// grown to [`GROWN_SAMPLES`]² samples with seed 1 ([`super::grow()`]); for both,
    /// `dh_um` and `h_max_um` override the crop's calibration (pixel size, height of grey
    /// level 1) as a sidecar would. Anything else is a path for [`HeightField::load`].
    ///
    /// Scan files (`.gsf`, `.gwy`) are read, levelled and reported as
    /// [`Source::load`] does with its defaults; what it reports is dropped here.
    pub fn load_source(
        spec: &str,
        dh_um: Option<f64>,
        h_max_um: Option<f64>,
    ) -> Result<HeightField> {
        let source = Source {
            dh_um,
            h_max_um,
            ..Source::new(spec)
        };
        source.load(&crate::report::Collect::default())
    }
}

/// Whether `spec` names a scan file (`.gsf`, `.gwy`).
pub fn is_scan(spec: &str) -> bool {
    scan_kind(Path::new(spec)).is_some()
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum ScanKind {
    Gsf,
    Gwy,
}

fn scan_kind(path: &Path) -> Option<ScanKind> {
    let ext = path.extension()?.to_string_lossy().to_ascii_lowercase();
    match ext.as_str() {
        "gsf" => Some(ScanKind::Gsf),
        "gwy" => Some(ScanKind::Gwy),
        _ => None,
    }
}

impl Source {
    /// `spec` with every option at its default.
    pub fn new(spec: impl Into<String>) -> Self {
        Self {
            spec: spec.into(),
            ..Self::default()
        }
    }

    /// The levelling that applies: the one asked for, or the format's default.
    pub fn levelling(&self) -> Result<Levelling> {
        match &self.level {
            Some(l) => l.parse(),
            None if is_scan(&self.spec) => Ok(Levelling::scan_default()),
            None => Ok(Levelling::default()),
        }
    }

    /// Checks the options without reading anything.
    pub fn validate(&self) -> Result<()> {
        self.levelling()?;
        if self.channel.is_some() && !is_scan(&self.spec) {
            return Err(Error::invalid(
                "channel",
                format!(
                    "--channel applies to scan files (.gsf, .gwy); {} has one channel",
                    self.spec
                ),
            ));
        }
        Ok(())
    }

    /// Reads, levels and tiles the field (module docs); what was done goes to `report`.
    pub fn load(&self, report: &dyn Report) -> Result<HeightField> {
        self.validate()?;
        let scan = is_scan(&self.spec);
        let raw = if scan {
            self.read_scan(report)?
        } else {
            super::io::read_source(&self.spec, self.dh_um, self.h_max_um)?
        };
        let steps = self.levelling()?;
        let levelled = if steps.0.is_empty() {
            raw
        } else {
            let (hf, rep) = level(&raw, &steps)?;
            report.note(&rep.line());
            for w in &rep.warnings {
                report.warn(w);
            }
            hf
        };
        if !(scan || self.tile.is_some()) {
            return Ok(levelled);
        }
        let share = seam_share(&levelled);
        let how = self.tile.unwrap_or(Tile::None);
        if how == Tile::None {
            report.note(&format!(
                "seam: {:.2} % of the spectral energy is the step where the tiled edges meet \
                 (--tile mirror|window|grow removes it)",
                share * 100.0
            ));
            return Ok(levelled);
        }
        let tiled = tile(&levelled, how)?;
        report.note(&format!(
            "seam: {:.2} % of the spectral energy; --tile {how}: {:.2} % ({}×{} samples)",
            share * 100.0,
            seam_share(&tiled) * 100.0,
            tiled.nx(),
            tiled.ny()
        ));
        Ok(tiled)
    }

    /// A scan's chosen channel in µm, with the sidecar's and the caller's overrides.
    fn read_scan(&self, report: &dyn Report) -> Result<HeightField> {
        let path = Path::new(&self.spec);
        crate::fsutil::check_input_file(path, "scan file", super::scan::MAX_SCAN_BYTES)?;
        let (side_dh, side_h_max) = super::io::sidecar_scale(path)?;
        let channel = match scan_kind(path) {
            Some(ScanKind::Gsf) => {
                let ch = super::gsf::read(path)?;
                let infos = [ch.info.clone()];
                if let Some(want) = &self.channel {
                    super::scan::choose_channel(path, &infos, Some(want))?;
                }
                ch
            }
            _ => {
                let file = super::gwy::GwyFile::read(path)?;
                let infos = file.channels(path)?;
                let i = super::scan::choose_channel(path, &infos, self.channel.as_deref())?;
                if let Some(n) = file.masked_points(path, i)? {
                    report.note(&format!(
                        "scan {}: the channel's mask marks {n} samples; diffract uses every \
                         sample as stored (Gwyddion fills invalid points under its mask)",
                        path.display()
                    ));
                }
                file.channel(path, i)?
            }
        };
        let hf = super::scan::to_heightfield(
            path,
            &channel,
            self.dh_um.or(side_dh),
            self.h_max_um.or(side_h_max),
        )?;
        let (ex, ey) = hf.extent_um();
        let unit = if channel.info.z_unit.is_empty() {
            "no unit"
        } else {
            &channel.info.z_unit
        };
        report.note(&format!(
            "scan {}: channel \"{}\" ({unit}), {}×{} samples, dH {:.2} nm, {ex:.2} × {ey:.2} µm",
            path.display(),
            channel.info.title,
            hf.nx(),
            hf.ny(),
            hf.dh_um() * 1e3
        ));
        Ok(hf)
    }
}
