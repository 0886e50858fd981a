//! A baker of chosen texels (`Baker::new_texels`, what a farm shard learns a basis on) gives
//! each texel, in any order and with its compact image's padding, the K, (u, v) and coverage of
//! the same texel in a bake of the whole image, bit for bit, under distant and point lights.
use ptm_bake::{BakeConfig, Baker, PreparedMesh};

fn cfg(light_distance: Option<f64>) -> BakeConfig {
    BakeConfig {
        res: [30, 26],
        spp: 4,
        seed: 7,
        light_distance,
        packets: true,
        threads: 0,
    }
}

/// Every light's K plane (and (u, v) plane) as bits, and the coverage.
fn planes(baker: &mut Baker, lights: &ptm_format::LightSet) -> (Vec<Vec<u32>>, Vec<Vec<[u32; 2]>>) {
    let (mut k, mut uv) = (Vec::new(), Vec::new());
    baker
        .trace(lights, &mut |_, plane, p| {
            k.push(plane.iter().map(|v| v.to_bits()).collect());
            uv.push(
                p.map(|p| p.iter().map(|x| x.map(f32::to_bits)).collect())
                    .unwrap_or_default(),
            );
            Ok(())
        })
        .unwrap();
    (k, uv)
}

#[test]
fn chosen_texels_equal_the_whole_bake_bit_for_bit() {
    let s = PreparedMesh::load("builtin:jersey", None).unwrap();
    let lights = ptm_bake::dome::fibonacci(9, 8.0).unwrap();
    // Out of order, one texel twice, edge texels, and 23 texels: a partial last packet.
    let texels: Vec<[usize; 2]> = [
        [29, 25],
        [0, 0],
        [5, 17],
        [13, 2],
        [13, 2],
        [28, 0],
        [0, 25],
        [7, 7],
        [8, 7],
        [9, 7],
        [21, 11],
        [3, 19],
        [17, 23],
        [29, 0],
        [1, 1],
        [2, 24],
        [14, 14],
        [15, 15],
        [16, 16],
        [22, 4],
        [11, 20],
        [26, 9],
        [19, 3],
    ]
    .to_vec();
    for r in [None, Some(4.0)] {
        let mut whole = Baker::new(&s, &cfg(r)).unwrap();
        let (wk, wuv) = planes(&mut whole, &lights);
        let mut some = Baker::new_texels(&s, &cfg(r), &texels).unwrap();
        let (sk, suv) = planes(&mut some, &lights);
        let rows = some.rows().len();
        assert_eq!(
            rows, 8,
            "23 texels in rows of 4, padded to whole 4×4 blocks"
        );
        assert_eq!(some.coverage().len(), 4 * rows);
        for (n, &[i, j]) in texels.iter().enumerate() {
            let t = j * 30 + i;
            assert_eq!(some.coverage()[n].to_bits(), whole.coverage()[t].to_bits());
            for l in 0..lights.len() {
                assert_eq!(sk[l][n], wk[l][t], "light {l}, texel ({i}, {j}), {r:?}");
                if r.is_some() {
                    assert_eq!(suv[l][n], wuv[l][t], "light {l}, texel ({i}, {j})");
                }
            }
        }
        // The padding sees nothing.
        assert!(some.coverage()[texels.len()..].iter().all(|&c| c == 0.0));
    }
    assert!(Baker::new_texels(&s, &cfg(None), &[[30, 0]]).is_err());
    assert!(Baker::new_texels(&s, &cfg(None), &[]).is_err());
}
