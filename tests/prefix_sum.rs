//! The GPU prefix sum against a CPU scan, across block and level boundaries.

mod common;

use firstshot::gpu::buffers;
use firstshot::stages::prefix_sum::{BLOCK, PrefixSum};

#[test]
fn exclusive_prefix_sums_match_the_cpu() {
    let Some(ctx) = common::gpu() else { return };
    let device = &ctx.device;
    // One value, a block minus/plus one, two levels, and past BLOCK^2 for three levels.
    for n in [1u32, BLOCK - 1, BLOCK, BLOCK + 1, 300_001, BLOCK * BLOCK + 5] {
        let mut state = 0x2545_f491_4f6c_dd1du64 ^ n as u64;
        let values: Vec<u32> = (0..n)
            .map(|_| {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                (state % 7) as u32
            })
            .collect();
        let input = buffers::storage_init(device, "test.values", &values, wgpu::BufferUsages::empty());
        let output = buffers::storage_zeroed(device, "test.scanned", 4 * n as u64, wgpu::BufferUsages::COPY_SRC);
        let scan = PrefixSum::new(device, n, &input, &output);
        let mut encoder = device.create_command_encoder(&Default::default());
        scan.record(&mut encoder);
        ctx.queue.submit([encoder.finish()]);
        let got: Vec<u32> = buffers::read_back(device, &ctx.queue, &output, 4 * n as u64).unwrap();
        let mut sum = 0u32;
        for (i, (&v, &g)) in values.iter().zip(&got).enumerate() {
            assert_eq!(g, sum, "n = {n}: element {i}");
            sum += v;
        }
    }
}
