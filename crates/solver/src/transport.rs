//! The interface every solver iterates on: how light moves between patches, as a whole
//! product ([`Transport`]) and, where it exists, as single rows and columns ([`Entries`]).

use crate::scene::Rgb;

/// How light moves between patches: what every solver needs from form factors. A dense matrix
/// and a hierarchical link list (`hierarchy::Hierarchy`) both implement it.
pub trait Transport: Sync {
    /// Number of patches (rows and columns).
    fn patch_count(&self) -> usize;

    /// `out_i = sum_j F_ij B_j` for every `i`: the irradiance each patch gathers from `radiosity`.
    fn gather(&self, radiosity: &[Rgb], out: &mut [Rgb]);

    /// Single rows and columns, for methods that update one patch at a time (Gauss-Seidel,
    /// progressive); `None` where the operator exists only as a whole product.
    fn entries(&self) -> Option<&dyn Entries> {
        None
    }
}

/// Single rows and columns of the form-factor matrix.
pub trait Entries: Sync {
    /// Irradiance gathered by patch `i` from `radiosity`: `sum_j F_ij B_j`.
    fn gather_row(&self, i: usize, radiosity: &[Rgb]) -> Rgb;

    /// Calls `visit(i, F_ij)` for every receiver `i` with a non-zero factor from source `j`.
    fn for_each_in_column(&self, j: usize, visit: &mut dyn FnMut(usize, f64));
}
