//! The sizes of one object's arrays in the kernels (`crate::filters::batched`): the
//! state size `n` and the measured size `d`.
//!
//! The factory makes few shapes (`d` in 1..=3, `n = d` or `n = 2 d`, see
//! `ClassTables::new`). For those the sizes are compile-time constants ([`Fixed`]), so
//! that a kernel's loops have constant bounds: the compiler unrolls them and drops their
//! bounds checks. The kernel's code is the same for every shape, the same operations in
//! the same order, so a [`Fixed`] shape gives the same values bit for bit as
//! [`Runtime`], which takes any other shape.

/// `n` and `d` of an object's arrays.
pub trait Shape: Copy {
    /// The state size `n`.
    fn n(self) -> usize;
    /// The measured size `d` (0 where a kernel does not use it).
    fn d(self) -> usize;
}

/// A shape known at compile time.
#[derive(Clone, Copy, Debug)]
pub struct Fixed<const N: usize, const D: usize>;

impl<const N: usize, const D: usize> Shape for Fixed<N, D> {
    #[inline(always)]
    fn n(self) -> usize {
        N
    }

    #[inline(always)]
    fn d(self) -> usize {
        D
    }
}

/// A shape known at run time only.
#[derive(Clone, Copy, Debug)]
pub struct Runtime {
    pub n: usize,
    pub d: usize,
}

impl Shape for Runtime {
    #[inline(always)]
    fn n(self) -> usize {
        self.n
    }

    #[inline(always)]
    fn d(self) -> usize {
        self.d
    }
}

/// `$body` with `$shape` the [`Shape`] of `($n, $d)`: a [`Fixed`] one for each shape the
/// factory makes, else [`Runtime`].
macro_rules! with_shape {
    ($n:expr, $d:expr, |$shape:ident| $body:expr) => {
        match ($n, $d) {
            (1, 1) => {
                let $shape = $crate::filters::shape::Fixed::<1, 1>;
                $body
            }
            (2, 1) => {
                let $shape = $crate::filters::shape::Fixed::<2, 1>;
                $body
            }
            (2, 2) => {
                let $shape = $crate::filters::shape::Fixed::<2, 2>;
                $body
            }
            (4, 2) => {
                let $shape = $crate::filters::shape::Fixed::<4, 2>;
                $body
            }
            (3, 3) => {
                let $shape = $crate::filters::shape::Fixed::<3, 3>;
                $body
            }
            (6, 3) => {
                let $shape = $crate::filters::shape::Fixed::<6, 3>;
                $body
            }
            (n, d) => {
                let $shape = $crate::filters::shape::Runtime { n, d };
                $body
            }
        }
    };
}

/// [`with_shape!`] for a kernel of the state alone (`d` is 0): `$n` in 1..=6.
macro_rules! with_state {
    ($n:expr, |$shape:ident| $body:expr) => {
        match $n {
            1 => {
                let $shape = $crate::filters::shape::Fixed::<1, 0>;
                $body
            }
            2 => {
                let $shape = $crate::filters::shape::Fixed::<2, 0>;
                $body
            }
            3 => {
                let $shape = $crate::filters::shape::Fixed::<3, 0>;
                $body
            }
            4 => {
                let $shape = $crate::filters::shape::Fixed::<4, 0>;
                $body
            }
            6 => {
                let $shape = $crate::filters::shape::Fixed::<6, 0>;
                $body
            }
            n => {
                let $shape = $crate::filters::shape::Runtime { n, d: 0 };
                $body
            }
        }
    };
}

pub(crate) use {with_shape, with_state};
