//! `ptm-runtime`: wgpu/WGSL shading of a cloth plane under spherical area lights, with penumbra-map
//! soft shadows from a planar caster and micro-occlusion from an occlusion PTM; and its CPU twin.
