//! The inverse of a committed scene's `origins`: the global index of an object's primitive,
//! for callers that name primitives as the C API reports them (object id, index inside the
//! object), e.g. the primitive a secondary ray leaves. It numbers every primitive of the
//! scene's objects, also those the committed scene left out (a disabled object's): the id
//! stays valid and names nothing there.

use super::PrimOrigin;
use crate::fallible::{self, Fallible};
use crate::geometry::{PrimIndex, INVALID};

/// Global index of each `(object, prim)`, object by object. Built on demand
/// (`Scene::ensure_prim_lookup`, 4 bytes per primitive of the objects, placed or not, and a
/// `usize` per object), like ropes and exact corners.
#[derive(Clone, Debug, Default)]
pub struct PrimLookup {
    /// Where object `o`'s entries start in `global`; `first[o + 1]` ends them.
    first: Vec<usize>,
    /// `INVALID` where the committed scene has no primitive of that index.
    global: Vec<PrimIndex>,
}

impl PrimLookup {
    /// The lookup of `origins` (`origins[g]` = where global primitive `g` came from) for
    /// objects of `counts` primitives each; every origin lies within them.
    pub fn new(
        origins: &[PrimOrigin],
        counts: impl ExactSizeIterator<Item = usize>,
    ) -> Fallible<Self> {
        let mut first = fallible::with_capacity(counts.len() + 1)?;
        first.push(0);
        for l in counts {
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

    /// The global index of primitive `prim` of object `object`: `None` if the object has no
    /// such primitive, `INVALID` if the committed scene left it out (its object is disabled).
    pub fn get(&self, object: u32, prim: u32) -> Option<PrimIndex> {
        let (o, p) = (object as usize, prim as usize);
        let (start, end) = (*self.first.get(o)?, *self.first.get(o.checked_add(1)?)?);
        (p < end - start).then(|| self.global[start + p])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_every_origin_and_tells_left_out_from_unknown() {
        let o = |object, prim| PrimOrigin { object, prim };
        // Object 1 (two primitives) was left out.
        let origins = [o(2, 2), o(0, 1), o(0, 0), o(2, 0), o(3, 0), o(2, 1)];
        let lookup = PrimLookup::new(&origins, [2, 2, 3, 1].into_iter()).unwrap();
        for (g, p) in origins.iter().enumerate() {
            assert_eq!(lookup.get(p.object, p.prim), Some(g as PrimIndex));
        }
        for (object, prim) in [(1, 0), (1, 1)] {
            assert_eq!(
                lookup.get(object, prim),
                Some(INVALID),
                "({object}, {prim})"
            );
        }
        for (object, prim) in [(0, 2), (1, 2), (2, 3), (3, 1), (4, 0), (u32::MAX, 0)] {
            assert_eq!(lookup.get(object, prim), None, "({object}, {prim})");
        }
    }
}
