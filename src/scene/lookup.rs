//! The inverse of a committed scene's `origins`: the global index of an object's primitive,
//! for callers that name primitives as the C API reports them (object id, index inside the
//! object), e.g. the primitive a secondary ray leaves.

use super::PrimOrigin;
use crate::fallible::{self, Fallible};
use crate::geometry::{PrimIndex, INVALID};

/// Global index of each `(object, prim)`, object by object. Built on demand
/// (`Scene::ensure_prim_lookup`, 4 bytes per primitive and a `usize` per object), like ropes
/// and exact corners.
#[derive(Clone, Debug, Default)]
pub struct PrimLookup {
    /// Where object `o`'s entries start in `global`; `first[o + 1]` ends them.
    first: Vec<usize>,
    /// `INVALID` where an object has no primitive of that index.
    global: Vec<PrimIndex>,
}

impl PrimLookup {
    /// The lookup of `origins` (`origins[g]` = where global primitive `g` came from) for
    /// `objects` objects.
    pub fn new(origins: &[PrimOrigin], objects: usize) -> Fallible<Self> {
        // Entries per object: its largest index + 1 (an object may have gaps).
        let mut len = fallible::filled(0usize, objects)?;
        for o in origins {
            let l = &mut len[o.object as usize];
            *l = (*l).max(o.prim as usize + 1);
        }
        let mut first = fallible::with_capacity(objects + 1)?;
        first.push(0);
        for l in len {
            first.push(first.last().copied().unwrap_or(0) + l);
        }
        let mut global = fallible::filled(INVALID, *first.last().unwrap_or(&0))?;
        for (g, o) in origins.iter().enumerate() {
            global[first[o.object as usize] + o.prim as usize] = g as PrimIndex;
        }
        Ok(PrimLookup { first, global })
    }

    /// Whether this is the lookup of a scene with primitives (an empty one is not built yet,
    /// or its scene has none).
    pub fn is_empty(&self) -> bool {
        self.global.is_empty()
    }

    /// Memory held, in bytes.
    pub fn bytes(&self) -> usize {
        std::mem::size_of_val(self.first.as_slice()) + std::mem::size_of_val(self.global.as_slice())
    }

    /// The global index of primitive `prim` of object `object`, if the scene has it.
    pub fn get(&self, object: u32, prim: u32) -> Option<PrimIndex> {
        let (o, p) = (object as usize, prim as usize);
        let (start, end) = (*self.first.get(o)?, *self.first.get(o.checked_add(1)?)?);
        if p >= end - start {
            return None;
        }
        let g = self.global[start + p];
        (g != INVALID).then_some(g)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_every_origin_and_nothing_else() {
        let o = |object, prim| PrimOrigin { object, prim };
        // Object 1 has no primitives; object 2 lacks index 1.
        let origins = [o(2, 2), o(0, 1), o(0, 0), o(2, 0), o(3, 0)];
        let lookup = PrimLookup::new(&origins, 4).unwrap();
        for (g, p) in origins.iter().enumerate() {
            assert_eq!(lookup.get(p.object, p.prim), Some(g as PrimIndex));
        }
        for (object, prim) in [
            (0, 2),
            (1, 0),
            (2, 1),
            (2, 3),
            (3, 1),
            (4, 0),
            (u32::MAX, 0),
        ] {
            assert_eq!(lookup.get(object, prim), None, "({object}, {prim})");
        }
    }
}
