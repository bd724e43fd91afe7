//! Node layouts: depth-first and van Emde Boas.
