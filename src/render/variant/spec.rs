//! The specialisation constants of the graphics stages, by name. `SpecConstant` is generated
//! by build.rs from the GLSL's `layout(constant_id = N)` declarations, so the ids here are
//! the shaders' own; [`Specialisation`] holds one value per constant and is indexed by them.

include!(concat!(env!("OUT_DIR"), "/spec_constants.rs"));

/// One value per specialisation constant (ints and VkBool32 alike are 32-bit), indexed by
/// [`SpecConstant`]; unset constants are 0.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub(crate) struct Specialisation([u32; SpecConstant::COUNT]);

impl Specialisation {
    /// The values in `constant_id` order, as the pipeline uploads them.
    pub fn values(&self) -> &[u32] {
        &self.0
    }
}

impl std::ops::Index<SpecConstant> for Specialisation {
    type Output = u32;
    fn index(&self, c: SpecConstant) -> &u32 {
        &self.0[c as usize]
    }
}

impl std::ops::IndexMut<SpecConstant> for Specialisation {
    fn index_mut(&mut self, c: SpecConstant) -> &mut u32 {
        &mut self.0[c as usize]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constants_are_numbered_by_their_glsl_ids() {
        for (i, c) in SpecConstant::ALL.into_iter().enumerate() {
            assert_eq!(c as usize, i);
            let decl = format!("layout(constant_id = {i}) const");
            let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/glsl");
            let found = std::fs::read_dir(dir).unwrap().any(|f| {
                let src = std::fs::read_to_string(f.unwrap().path()).unwrap_or_default();
                src.lines().any(|l| {
                    l.starts_with(&decl) && l.split_whitespace().any(|w| w == c.glsl_name())
                })
            });
            assert!(found, "{} is constant_id {i} in the GLSL", c.glsl_name());
        }
        let mut s = Specialisation::default();
        s[SpecConstant::Storage] = 2;
        assert_eq!(s.values()[SpecConstant::Storage as usize], 2);
    }
}
