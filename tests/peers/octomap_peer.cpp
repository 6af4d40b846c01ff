// OctoMap's side of tests/octomap.rs and benches/octomap.rs: build an OcTree with OctoMap
// 1.9 itself from the same scans our octree gets, time each insertion, write its .bt and .ot.
//
// Build: g++ -O2 -std=c++17 octomap_peer.cpp -loctomap -loctomath -o octomap_peer
// Usage: octomap_peer SCANS.bin RESOLUTION OUT_PREFIX
// SCANS.bin: repeated { u32 n; f32 origin[3]; f64 max_range; f32 xyz[3 n] }, little-endian.
// Prints one JSON object: per-scan insertion milliseconds, leaf and node counts, memory.
#include <octomap/octomap.h>

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <vector>

int main(int argc, char** argv) {
  if (argc != 4) {
    std::cerr << "usage: octomap_peer SCANS.bin RESOLUTION OUT_PREFIX\n";
    return 2;
  }
  std::ifstream in(argv[1], std::ios::binary);
  if (!in) {
    std::cerr << "cannot read " << argv[1] << "\n";
    return 2;
  }
  octomap::OcTree tree(std::stod(argv[2]));
  std::vector<double> ms;
  while (true) {
    uint32_t n = 0;
    float origin[3];
    double max_range = -1.0;
    if (!in.read(reinterpret_cast<char*>(&n), 4)) break;
    in.read(reinterpret_cast<char*>(origin), 12);
    in.read(reinterpret_cast<char*>(&max_range), 8);
    std::vector<float> xyz(3 * static_cast<size_t>(n));
    in.read(reinterpret_cast<char*>(xyz.data()), 12 * static_cast<std::streamsize>(n));
    if (!in) {
      std::cerr << "truncated scan\n";
      return 2;
    }
    octomap::Pointcloud cloud;
    cloud.reserve(n);
    for (uint32_t i = 0; i < n; ++i) cloud.push_back(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]);
    auto t0 = std::chrono::steady_clock::now();
    tree.insertPointCloud(cloud, octomap::point3d(origin[0], origin[1], origin[2]), max_range, false, false);
    auto t1 = std::chrono::steady_clock::now();
    ms.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
  }
  size_t leafs = 0, occupied = 0;
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
    ++leafs;
    if (tree.isNodeOccupied(*it)) ++occupied;
  }
  size_t nodes = tree.size();
  size_t memory = tree.memoryUsage();
  std::string prefix = argv[3];
  // .ot first: writeBinary turns the tree into maximum likelihood and prunes it.
  tree.write(prefix + ".ot");
  tree.writeBinary(prefix + ".bt");
  std::printf("{\"ms\": [");
  for (size_t i = 0; i < ms.size(); ++i) std::printf("%s%.4f", i ? ", " : "", ms[i]);
  std::printf("], \"leafs\": %zu, \"occupied_leafs\": %zu, \"nodes\": %zu, \"memory_bytes\": %zu}\n", leafs,
              occupied, nodes, memory);
  return 0;
}
