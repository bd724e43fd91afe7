//! The inverse of a committed scene's `origins`: the global index of an object's primitive,
//! for callers that name primitives as the C API reports them (object id, index inside the
//! object), e.g. the primitive a secondary ray leaves. It numbers every primitive of the
//! scene's objects, also those the committed scene left out (a disabled object's): the id
//! stays valid and names nothing there. A removed object has no entries: its id names
//! nothing, and the lookup tells it from an id never given.

use super::PrimOrigin;
use crate::fallible::{self, Fallible, TryGrow};
use crate::geometry::{PrimIndex, INVALID};

/// Global index of each `(object, prim)`, object by object. Built on demand
/// (`Scene::ensure_prim_lookup`, 4 bytes per primitive of the objects, placed or not, a
/// `usize` per object id and 4 bytes per removed id), like ropes and exact corners.
#[derive(Clone, Debug, Default)]
pub struct PrimLookup {
    /// Where object `o`'s entries start in `global`; `first[o + 1]` ends them.
    first: Vec<usize>,
    /// `INVALID` where the committed scene has no primitive of that index.
    global: Vec<PrimIndex>,
    /// The removed objects' ids, ascending.
    removed: Vec<u32>,
}

impl PrimLookup {
    /// The lookup of `origins` (`origins[g]` = where global primitive `g` came from) for
    /// objects of `counts` primitives each (`None`: the object was removed); every origin
    /// lies within them.
    pub fn new(
        origins: &[PrimOrigin],
        counts: impl ExactSizeIterator<Item = Option<usize>>,
    ) -> Fallible<Self> {
        let mut first = fallible::with_capacity(counts.len() + 1)?;
        let mut removed = Vec::new();
        first.push(0);
        for (object, l) in counts.enumerate() {
            if l.is_none() {
                removed.try_push(object as u32)?;
            }
            first.push(first.last().copied().unwrap_or(0) + l.unwrap_or(0));
        }
        let mut global = fallible::filled(INVALID, *first.last().unwrap_or(&0))?;
        for (g, o) in origins.iter().enumerate() {
            global[first[o.object as usize] + o.prim as usize] = g as PrimIndex;
        }
        Ok(PrimLookup {
            first,
            global,
            removed,
        })
    }

    /// Whether this is the lookup of a scene with primitives (an empty one is not built yet,
    /// or its scene has none).
    pub fn is_empty(&self) -> bool {
        self.global.is_empty()
    }

    /// Memory held, in bytes.
    pub fn bytes(&self) -> usize {
        std::mem::size_of_val(self.first.as_slice())
            + std::mem::size_of_val(self.global.as_slice())
            + std::mem::size_of_val(self.removed.as_slice())
    }

    /// Whether `object` is the id of a removed object (which [`Self::get`] knows as `None`).
    pub fn removed(&self, object: u32) -> bool {
        self.removed.binary_search(&object).is_ok()
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
    fn finds_every_origin_and_tells_left_out_removed_and_unknown_apart() {
        let o = |object, prim| PrimOrigin { object, prim };
        // Object 1 (two primitives) was left out, objects 4 and 6 were removed.
        let origins = [
            o(2, 2),
            o(0, 1),
            o(0, 0),
            o(2, 0),
            o(3, 0),
            o(2, 1),
            o(5, 0),
        ];
        let counts = [Some(2), Some(2), Some(3), Some(1), None, Some(1), None];
        let lookup = PrimLookup::new(&origins, counts.into_iter()).unwrap();
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
        for (object, prim) in [(0, 2), (1, 2), (2, 3), (3, 1), (4, 0), (6, 0), (7, 0)] {
            assert_eq!(lookup.get(object, prim), None, "({object}, {prim})");
        }
        assert_eq!(lookup.get(u32::MAX, 0), None);
        let removed: Vec<u32> = (0..9).filter(|&o| lookup.removed(o)).collect();
        assert_eq!(removed, [4, 6]);
    }
}
