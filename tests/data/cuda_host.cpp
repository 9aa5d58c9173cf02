// The CUDA lane kernel built for the host (tests/cuda_host.rs): reads a run and its lanes'
// parameters from a binary file, runs `vs_lane` on every lane, writes the sums.
//
// Input, little-endian: 10 int64 (gpu_lanes.rs `Shared::ints`), float64 f_s, int64 lanes, then
// nine arrays, each an int64 length and its float64s: x, v, a, j, drive, basis, osc, the varying
// fields' records, the shared fields' values (`vs_u`); then the three words of the varying
// fields' mask (`vs_vary`).
// Output: lanes × out_fields float64s, field-major.
#include "../../crates/kernel/src/cuda/lane.cu"
#include <cstdio>
#include <cstdlib>
#include <vector>

static long long read_i64(FILE *f) {
  long long v = 0;
  if (fread(&v, 8, 1, f) != 1) { fprintf(stderr, "short input\n"); std::exit(2); }
  return v;
}

static std::vector<double> read_array(FILE *f) {
  std::vector<double> v((size_t)read_i64(f));
  if (fread(v.data(), 8, v.size(), f) != v.size()) { fprintf(stderr, "short input\n"); std::exit(2); }
  return v;
}

int main(int argc, char **argv) {
  if (argc != 3) { fprintf(stderr, "usage: cuda_host IN OUT\n"); return 2; }
  FILE *in = fopen(argv[1], "rb");
  if (!in) { perror(argv[1]); return 2; }
  long long ints[10];
  for (long long &i : ints) i = read_i64(in);
  double f_s;
  if (fread(&f_s, 8, 1, in) != 1) return 2;
  long long n = read_i64(in);
  std::vector<double> arr[9];
  for (auto &a : arr) a = read_array(in);
  for (vs_u64 &w : vs_vary) w = (vs_u64)read_i64(in);
  fclose(in);
  if (arr[8].size() != VS_LANE_FIELDS) { fprintf(stderr, "vs_u: wrong length\n"); return 2; }
  for (int f = 0; f < VS_LANE_FIELDS; ++f) vs_u[f] = arr[8][f];
  vs_effects = ints[9];
  VsRun r = {ints[0], ints[1], ints[2], ints[3], ints[4], ints[5], ints[6], ints[7], ints[8], ints[9], f_s,
             arr[0].data(), arr[1].data(), arr[2].data(), arr[3].data(), arr[4].data(),
             arr[5].data(), arr[6].data()};
  std::vector<double> out((size_t)((VS_OSC_PEAK + ints[7]) * n));
  for (long long l = 0; l < n; ++l) vs_lane(r, arr[7].data(), out.data(), n, l);
  FILE *o = fopen(argv[2], "wb");
  if (!o || fwrite(out.data(), 8, out.size(), o) != out.size()) { perror(argv[2]); return 2; }
  fclose(o);
  return 0;
}
