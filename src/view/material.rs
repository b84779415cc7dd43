//! Live material edits: the scene's material with the viewer's [`MaterialEdit`] applied,
//! loaded and prepared on a worker thread, so the window keeps drawing the old material
//! meanwhile. Loaded height fields are kept unscaled: a height step reuses the field (a
//! grown Elaphe patch takes a second to grow) and only multiplies its heights.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

use super::input::MaterialEdit;
use crate::brdf::truncation::{Precision, Reach};
use crate::heightfield::HeightField;
use crate::material::{Material, PreparedMaterial};
use crate::{Error, Result};

/// Which loaded field: its source and everything it was loaded with.
type FieldKey = (
    String,
    Option<u64>,
    Option<u64>,
    Option<String>,
    Option<String>,
    Option<crate::heightfield::Tile>,
);

/// Loads edited materials one at a time on a worker thread; the newest edit wins.
pub(super) struct MaterialLoader {
    /// The scene's material (with the command line's overrides): edits apply to it.
    base: Material,
    cache_dir: Option<PathBuf>,
    fields: Arc<Mutex<HashMap<FieldKey, Arc<HeightField>>>>,
    running: Option<(MaterialEdit, JoinHandle<Result<PreparedMaterial>>)>,
    /// The edit the controls ask for now.
    wanted: MaterialEdit,
    /// The edit of the last material handed out.
    current: MaterialEdit,
}

/// What an edit describes: the material, and the factor on its loaded field's heights.
/// Every key (`Z`/`X`, `K`/`L`, `N`) edits through it.
struct Edited {
    material: Material,
    height_scale: f64,
}

/// The material `edit` makes of `base`.
fn edited(base: &Material, edit: MaterialEdit) -> Edited {
    let mut m = base.clone();
    if edit.field != 0 {
        // A shipped field at its own calibration: the scene's overrides were for its field.
        m.heightfield = edit.heightfield(&base.heightfield).to_string();
        m.dh_um = None;
        m.h_max_um = None;
        m.channel = None;
        m.level = None;
        m.tile = None;
    }
    m.coherence_um *= edit.coherence_scale();
    Edited {
        material: m,
        height_scale: edit.height_scale(),
    }
}

fn field_key(m: &Material) -> FieldKey {
    (
        m.heightfield.clone(),
        m.dh_um.map(f64::to_bits),
        m.h_max_um.map(f64::to_bits),
        m.channel.clone(),
        m.level.clone(),
        m.tile,
    )
}

impl MaterialLoader {
    /// `loaded`: the scene's height field as the viewer started with it.
    pub fn new(base: Material, cache_dir: Option<PathBuf>, loaded: &HeightField) -> Self {
        let fields = HashMap::from([(field_key(&base), Arc::new(loaded.clone()))]);
        Self {
            base,
            cache_dir,
            fields: Arc::new(Mutex::new(fields)),
            running: None,
            wanted: MaterialEdit::default(),
            current: MaterialEdit::default(),
        }
    }

    /// The controls ask for `edit`: loaded now if no load runs, else after it.
    pub fn want(&mut self, edit: MaterialEdit) -> Result<()> {
        self.wanted = edit;
        self.start()
    }

    /// Whether a load runs.
    pub fn loading(&self) -> bool {
        self.running.is_some()
    }

    fn start(&mut self) -> Result<()> {
        if self.running.is_some() || self.wanted == self.current {
            return Ok(());
        }
        let edit = self.wanted;
        let target = edited(&self.base, edit);
        let fields = Arc::clone(&self.fields);
        let cache_dir = self.cache_dir.clone();
        let handle = std::thread::Builder::new()
            .name("material load".into())
            .spawn(move || load(&target, &fields, cache_dir))
            .map_err(|e| Error::invalid("material load", format!("no worker thread: {e}")))?;
        self.running = Some((edit, handle));
        Ok(())
    }

    /// A finished load, if any. A failed load (a field that
    /// cannot be planned at this height, say) is an error; the controls' edit is then taken
    /// back to the material still shown. The next wanted edit starts loading.
    pub fn poll(&mut self) -> Option<Result<PreparedMaterial>> {
        if !self.running.as_ref()?.1.is_finished() {
            return None;
        }
        let (edit, handle) = self.running.take()?;
        let result = match handle.join() {
            Ok(r) => r,
            Err(_) => Err(Error::invalid("material load", "its worker panicked")),
        };
        match &result {
            Ok(_) => self.current = edit,
            // Back to what is shown: the same edit is not retried on its own.
            Err(_) if self.wanted == edit => self.wanted = self.current,
            Err(_) => {}
        }
        if let Err(e) = self.start() {
            return Some(Err(e));
        }
        Some(result)
    }

    /// The edit of the material handed out last (what the controls go back to after an
    /// error).
    pub fn current(&self) -> MaterialEdit {
        self.current
    }
}

impl Drop for MaterialLoader {
    fn drop(&mut self) {
        if let Some((_, h)) = self.running.take() {
            let _ = h.join();
        }
    }
}

/// Loads (or reuses) the field, scales it and prepares the material; the DFT terms wait
/// for a variant that reads them.
fn load(
    target: &Edited,
    fields: &Mutex<HashMap<FieldKey, Arc<HeightField>>>,
    cache_dir: Option<PathBuf>,
) -> Result<PreparedMaterial> {
    let material = &target.material;
    material.validate()?;
    let key = field_key(material);
    let kept = fields.lock().ok().and_then(|f| f.get(&key).cloned());
    let field = match kept {
        Some(f) => f,
        None => {
            let f = Arc::new(material.load_heightfield(&crate::report::Collect::default())?);
            if let Ok(mut m) = fields.lock() {
                m.insert(key, Arc::clone(&f));
            }
            f
        }
    };
    // Unscaled (the factor 1 exactly): the kept field itself.
    let hf = if target.height_scale == 1.0 {
        (*field).clone()
    } else {
        field.scaled(target.height_scale)?
    };
    let plan = material.plan_loaded(&hf, &Reach::ALL, Precision::F32, &crate::report::Stderr)?;
    material.prepare_planned_deferred(hf, plan, cache_dir.as_deref())
}
