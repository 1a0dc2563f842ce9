//! Forward-mode dual numbers for the f64 twins: a value and its derivatives with respect to `N`
//! inputs. The twins write each output once, as a function of its inputs, and get the exact
//! derivative by evaluating it on duals; the kernels' hand-written adjoints are checked against
//! that, so the twin's gradient does not share a derivation with the code it checks.

use std::ops::{Add, Div, Mul, Neg, Sub};

/// `value + Σ grad[i] ε_i`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Dual<const N: usize> {
    /// The value.
    pub value: f64,
    /// Its derivative with respect to each input.
    pub grad: [f64; N],
}

impl<const N: usize> Dual<N> {
    /// A constant.
    pub fn constant(value: f64) -> Self {
        Self {
            value,
            grad: [0.0; N],
        }
    }

    /// Input `i` of the function.
    pub fn input(value: f64, i: usize) -> Self {
        let mut grad = [0.0; N];
        grad[i] = 1.0;
        Self { value, grad }
    }

    fn map(self, value: f64, slope: f64) -> Self {
        let mut grad = self.grad;
        grad.iter_mut().for_each(|g| *g *= slope);
        Self { value, grad }
    }

    /// `1 / self`.
    pub fn recip(self) -> Self {
        let r = 1.0 / self.value;
        self.map(r, -r * r)
    }

    /// `self` clamped to `[lo, hi]`: no derivative where the clamp binds.
    pub fn clamp(self, lo: f64, hi: f64) -> Self {
        if self.value < lo {
            Self::constant(lo)
        } else if self.value > hi {
            Self::constant(hi)
        } else {
            self
        }
    }

    /// The larger of `self` and a constant (the constant's derivative, zero, where it is larger).
    pub fn max_constant(self, c: f64) -> Self {
        if self.value < c {
            Self::constant(c)
        } else {
            self
        }
    }
}

impl<const N: usize> Add for Dual<N> {
    type Output = Self;
    fn add(self, o: Self) -> Self {
        let mut grad = self.grad;
        grad.iter_mut().zip(o.grad).for_each(|(g, h)| *g += h);
        Self {
            value: self.value + o.value,
            grad,
        }
    }
}

impl<const N: usize> Sub for Dual<N> {
    type Output = Self;
    fn sub(self, o: Self) -> Self {
        self + (-o)
    }
}

impl<const N: usize> Neg for Dual<N> {
    type Output = Self;
    fn neg(self) -> Self {
        self.map(-self.value, -1.0)
    }
}

impl<const N: usize> Mul for Dual<N> {
    type Output = Self;
    fn mul(self, o: Self) -> Self {
        let mut grad = [0.0; N];
        for (i, g) in grad.iter_mut().enumerate() {
            *g = self.grad[i] * o.value + self.value * o.grad[i];
        }
        Self {
            value: self.value * o.value,
            grad,
        }
    }
}

impl<const N: usize> Mul<f64> for Dual<N> {
    type Output = Self;
    fn mul(self, c: f64) -> Self {
        self.map(self.value * c, c)
    }
}

impl<const N: usize> Div for Dual<N> {
    type Output = Self;
    fn div(self, o: Self) -> Self {
        let q = self.value / o.value;
        let mut grad = [0.0; N];
        for (i, g) in grad.iter_mut().enumerate() {
            *g = (self.grad[i] - q * o.grad[i]) / o.value;
        }
        Self { value: q, grad }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_quotient_of_products_has_the_calculus_derivative() {
        // f(x, y) = x y / (x + y) at (2, 3): ∂f/∂x = y² / (x + y)², ∂f/∂y = x² / (x + y)².
        let x = Dual::<2>::input(2.0, 0);
        let y = Dual::<2>::input(3.0, 1);
        let f = x * y / (x + y);
        assert!((f.value - 1.2).abs() < 1e-15);
        assert!((f.grad[0] - 9.0 / 25.0).abs() < 1e-15);
        assert!((f.grad[1] - 4.0 / 25.0).abs() < 1e-15);
        assert_eq!(Dual::<2>::input(5.0, 0).clamp(0.0, 1.0).grad, [0.0, 0.0]);
        assert_eq!(Dual::<2>::input(0.5, 0).clamp(0.0, 1.0).grad, [1.0, 0.0]);
    }
}
