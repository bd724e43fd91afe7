// Parallel inclusive prefix sum (Hillis & Steele within a workgroup, block sums scanned one
// level up and added back): the compaction of the wavefront render path (thesis §3.3).
struct ScanParams { count: u32, pad0: u32, pad1: u32, pad2: u32 }

@group(0) @binding(0) var<uniform> sp: ScanParams;                   // elements of this level
@group(0) @binding(1) var<storage, read_write> data: array<u32>;     // the level, scanned in place
@group(0) @binding(2) var<storage, read_write> sums: array<u32>;     // one total per workgroup

var<workgroup> tile: array<u32, 64>;

fn scan_id(wid: vec3<u32>, lid: vec3<u32>, nwg: vec3<u32>) -> u32 {
    return (wid.y * nwg.x + wid.x) * 64u + lid.x;
}

@compute @workgroup_size(64)
fn scan_local(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = scan_id(wid, lid, nwg);
    var v = 0u;
    if (i < sp.count) { v = data[i]; }
    tile[lid.x] = v;
    for (var off = 1u; off < 64u; off *= 2u) {
        workgroupBarrier();
        var add = 0u;
        if (lid.x >= off) { add = tile[lid.x - off]; }
        workgroupBarrier();
        tile[lid.x] += add;
    }
    workgroupBarrier();
    if (i < sp.count) { data[i] = tile[lid.x]; }
    // Guarded: a 2-D grid may run workgroups past the end.
    if (lid.x == 63u && i - 63u < sp.count) { sums[i / 64u] = tile[63]; }
}

// Adds the scanned total of all earlier workgroups.
@compute @workgroup_size(64)
fn scan_add(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = scan_id(wid, lid, nwg);
    if (i >= sp.count) { return; }
    let block = i / 64u;
    if (block > 0u) { data[i] += sums[block - 1u]; }
}
