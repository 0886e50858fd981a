//! Acceleration structures of a bake: one BLAS of the tile's mesh (in the baker's units), and a
//! TLAS per set of tile copies, each copy an instance of that BLAS shifted by whole tiles. The
//! sets come from `ptm_bake::tiling`, the rule the CPU bake uses: only the copies that can
//! shadow the centre tile for a light, so both tracers see the same geometry.
use std::collections::HashMap;

use crate::adapter::Gpu;
use crate::{Error, Result};

/// The tile's BLAS and the TLASes built so far, by copy set.
pub struct Scene {
    blas: wgpu::Blas,
    tile: [f64; 2],
    tlas: HashMap<Vec<[i32; 2]>, wgpu::Tlas>,
    // Kept alive while the BLAS may be rebuilt from them (never, but wgpu validates builds).
    _vertices: wgpu::Buffer,
    _indices: wgpu::Buffer,
}

impl Scene {
    /// Checks a mesh of `vertices` and `triangles` against the limits `l` of the device on
    /// `adapter` (described), before anything is uploaded.
    pub fn check(l: &wgpu::Limits, adapter: &str, vertices: usize, triangles: usize) -> Result<()> {
        let too_big = |what: String, need: u64, limit: u64, limit_name| Error::TooBig {
            what,
            need,
            limit,
            limit_name,
            adapter: adapter.to_string(),
        };
        if triangles as u64 > l.max_blas_primitive_count as u64 {
            return Err(too_big(
                "the mesh's triangles".into(),
                triangles as u64,
                l.max_blas_primitive_count as u64,
                "max_blas_primitive_count",
            ));
        }
        let vb = vertices as u64 * 12;
        let ib = triangles as u64 * 12;
        if vb.max(ib) > l.max_buffer_size {
            return Err(too_big(
                format!("the mesh's vertex or index buffer ({vertices} vertices, {triangles} triangles), in bytes"),
                vb.max(ib),
                l.max_buffer_size,
                "max_buffer_size",
            ));
        }
        Ok(())
    }

    /// Uploads the mesh (`positions`, `triangles`: baker units) and builds its BLAS.
    pub fn new(
        gpu: &Gpu,
        positions: &[[f32; 3]],
        triangles: &[[u32; 3]],
        tile: [f64; 2],
    ) -> Result<Scene> {
        Scene::check(&gpu.limits, &gpu.name, positions.len(), triangles.len())?;
        let d = &gpu.device;
        let upload = |label, bytes: &[u8]| {
            let b = d.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: (bytes.len() as u64).next_multiple_of(4).max(4),
                usage: wgpu::BufferUsages::BLAS_INPUT | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            gpu.queue.write_buffer(&b, 0, bytes);
            b
        };
        let vertices = upload("tile vertices", bytemuck::cast_slice(positions));
        let indices = upload("tile triangles", bytemuck::cast_slice(triangles));
        gpu.wait("uploading the mesh")?;
        let size = wgpu::BlasTriangleGeometrySizeDescriptor {
            vertex_format: wgpu::VertexFormat::Float32x3,
            vertex_count: positions.len() as u32,
            index_format: Some(wgpu::IndexFormat::Uint32),
            index_count: Some(triangles.len() as u32 * 3),
            flags: wgpu::AccelerationStructureGeometryFlags::OPAQUE,
        };
        let blas = d.create_blas(
            &wgpu::CreateBlasDescriptor {
                label: Some("tile"),
                flags: wgpu::AccelerationStructureFlags::PREFER_FAST_TRACE,
                update_mode: wgpu::AccelerationStructureUpdateMode::Build,
            },
            wgpu::BlasGeometrySizeDescriptors::Triangles {
                descriptors: vec![size.clone()],
            },
        );
        let entry = wgpu::BlasBuildEntry {
            blas: &blas,
            geometry: wgpu::BlasGeometries::TriangleGeometries(vec![wgpu::BlasTriangleGeometry {
                size: &size,
                vertex_buffer: &vertices,
                first_vertex: 0,
                vertex_stride: 12,
                index_buffer: Some(&indices),
                first_index: Some(0),
                transform_buffer: None,
                transform_buffer_offset: None,
            }]),
        };
        let mut enc = d.create_command_encoder(&Default::default());
        enc.build_acceleration_structures(std::iter::once(&entry), std::iter::empty());
        gpu.queue.submit([enc.finish()]);
        gpu.wait("building the mesh's BLAS")?;
        Ok(Scene {
            blas,
            tile,
            tlas: HashMap::new(),
            _vertices: vertices,
            _indices: indices,
        })
    }

    /// Builds the TLAS of `copies` (tile offsets (a, b)) unless built already.
    pub fn prepare(&mut self, gpu: &Gpu, copies: &[[i32; 2]]) -> Result<()> {
        if self.tlas.contains_key(copies) {
            return Ok(());
        }
        let limit = gpu.limits.max_tlas_instance_count;
        if copies.len() as u64 > limit as u64 {
            return Err(Error::TooBig {
                what: "the tile copies one light needs".into(),
                need: copies.len() as u64,
                limit: limit as u64,
                limit_name: "max_tlas_instance_count",
                adapter: gpu.name.clone(),
            });
        }
        let mut tlas = gpu.device.create_tlas(&wgpu::CreateTlasDescriptor {
            label: Some("tile copies"),
            max_instances: copies.len().max(1) as u32,
            flags: wgpu::AccelerationStructureFlags::PREFER_FAST_TRACE,
            update_mode: wgpu::AccelerationStructureUpdateMode::Build,
        });
        for (i, c) in copies.iter().enumerate() {
            // Whole-tile shifts, rounded to f32 as the CPU bake's instance offsets are.
            let (x, y) = (
                (c[0] as f64 * self.tile[0]) as f32,
                (c[1] as f64 * self.tile[1]) as f32,
            );
            let transform = [1.0, 0.0, 0.0, x, 0.0, 1.0, 0.0, y, 0.0, 0.0, 1.0, 0.0];
            tlas[i] = Some(wgpu::TlasInstance::new(&self.blas, transform, 0, 0xff));
        }
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        enc.build_acceleration_structures(std::iter::empty(), std::iter::once(&tlas));
        gpu.queue.submit([enc.finish()]);
        self.tlas.insert(copies.to_vec(), tlas);
        Ok(())
    }

    /// The TLAS of `copies` ([`Scene::prepare`]d).
    pub fn tlas(&self, copies: &[[i32; 2]]) -> &wgpu::Tlas {
        &self.tlas[copies]
    }

    /// TLASes built.
    pub fn tlas_count(&self) -> usize {
        self.tlas.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_mesh_over_the_limits_is_refused_with_the_figures() {
        let l = wgpu::Limits {
            max_blas_primitive_count: 16_777_215,
            max_buffer_size: 1 << 20,
            ..wgpu::Limits::default()
        };
        assert!(Scene::check(&l, "dev", 1000, 16_777_215 / 1000).is_ok());
        let e = Scene::check(&l, "dev", 3, 16_777_216).unwrap_err();
        assert!(matches!(
            e,
            Error::TooBig {
                need: 16_777_216,
                limit: 16_777_215,
                limit_name: "max_blas_primitive_count",
                ..
            }
        ));
        assert_eq!(
            e.to_string(),
            "the mesh's triangles: 16777216 exceeds the device's max_blas_primitive_count of \
             16777215 (dev)"
        );
        let e = Scene::check(&l, "dev", 100_000, 10).unwrap_err();
        assert!(
            matches!(
                e,
                Error::TooBig {
                    need: 1_200_000,
                    limit_name: "max_buffer_size",
                    ..
                }
            ),
            "{e}"
        );
    }
}
