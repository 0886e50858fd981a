//! The convolution: a filtered planar image ([`Plane`]: the caster's opacity for shadows) averaged
//! over a kernel whose size varies per pixel, by one of several methods. This is the extension
//! point for new kernels and methods: each method is one module here that owns its WGSL (the
//! lookup included into the shading pass, and any passes run before it), its CPU twin, the
//! resources it prepares and uploads, and the kernels it supports ([`Method`]). Nothing outside
//! this folder names a method's buffers; the shading pass calls `blur_lookup(li, t, wt, shear, kernel)`
//! (image texel coordinate t, kernel radii wt in texels and shear, light li, `Kernel`) and the twin calls
//! [`Method::blur_lookup`].
//!
//! Adding a method: a [`crate::Blur`] value, a module implementing [`Method`], its arm in
//! [`method`], and its bindings in [`crate::bindings::shade`]. The variant tests then validate
//! its WGSL in every scene shape, check its bindings against naga and its twin list.

pub mod explicit;
mod method;
pub mod mip;
pub mod sat;
pub mod separable;

pub(crate) use method::own;
pub use method::{nothing, Blur, Bound, Built, Kernel, Method, Plane, Prepared};

/// The method of `blur`.
pub fn method(blur: Blur) -> &'static dyn Method {
    match blur {
        Blur::Explicit => &explicit::Explicit,
        Blur::Sat => &sat::Sat,
        Blur::Mip => &mip::Mip,
        Blur::Separable => &separable::Separable,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_blur_has_its_method_and_says_its_kernels() {
        for b in Blur::ALL {
            let m = method(b);
            assert_eq!(m.blur(), b);
            assert!(!m.kernels().is_empty(), "{}", b.name());
            assert!(m.wgsl().contains("fn blur_lookup("), "{}", b.name());
        }
    }
}
