// OctoMap's side of tests/octomap.rs and benches/octomap.rs: build an OcTree with OctoMap
// 1.9 itself from the same scans our octree gets, time each insertion, write its .bt and .ot.
//
// Build: g++ -O2 -std=c++17 octomap_peer.cpp -loctomap -loctomath -o octomap_peer
// Usage: octomap_peer SCANS.bin RESOLUTION OUT_PREFIX [color]
// SCANS.bin: repeated { u32 n; f32 origin[3]; f64 max_range; f32 xyz[3 n] }, little-endian;
// with `color` each scan also carries u8 rgb[3 n] after its points, and the tree is a
// ColorOcTree: after each insertPointCloud, every point within range colours its node with
// averageNodeColor (as octomap_server does), and updateInnerOccupancy runs before writing.
// Prints one JSON object: per-scan insertion milliseconds, leaf and node counts, memory.
#include <octomap/ColorOcTree.h>
#include <octomap/octomap.h>

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <vector>

template <class Tree>
int run(std::ifstream& in, Tree& tree, const std::string& prefix, bool color);

int main(int argc, char** argv) {
  if (argc != 4 && !(argc == 5 && std::string(argv[4]) == "color")) {
    std::cerr << "usage: octomap_peer SCANS.bin RESOLUTION OUT_PREFIX [color]\n";
    return 2;
  }
  std::ifstream in(argv[1], std::ios::binary);
  if (!in) {
    std::cerr << "cannot read " << argv[1] << "\n";
    return 2;
  }
  if (argc == 5) {
    octomap::ColorOcTree tree(std::stod(argv[2]));
    return run(in, tree, argv[3], true);
  }
  octomap::OcTree tree(std::stod(argv[2]));
  return run(in, tree, argv[3], false);
}

template <class Tree>
void colour(Tree&, const octomap::Pointcloud&, const std::vector<uint8_t>&, const octomap::point3d&, double) {}

template <>
void colour(octomap::ColorOcTree& tree, const octomap::Pointcloud& cloud, const std::vector<uint8_t>& rgb,
            const octomap::point3d& origin, double max_range) {
  for (size_t i = 0; i < cloud.size(); ++i) {
    const octomap::point3d& p = cloud[i];
    // The points insertPointCloud marked occupied (computeUpdate's test).
    if (max_range < 0.0 || (p - origin).norm() <= max_range)
      tree.averageNodeColor(p.x(), p.y(), p.z(), rgb[3 * i], rgb[3 * i + 1], rgb[3 * i + 2]);
  }
}

template <class Tree>
void finish(Tree&) {}

template <>
void finish(octomap::ColorOcTree& tree) {
  tree.updateInnerOccupancy();
}

template <class Tree>
int run(std::ifstream& in, Tree& tree, const std::string& prefix, bool color) {
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
    std::vector<uint8_t> rgb(color ? 3 * static_cast<size_t>(n) : 0);
    if (color) in.read(reinterpret_cast<char*>(rgb.data()), 3 * static_cast<std::streamsize>(n));
    if (!in) {
      std::cerr << "truncated scan\n";
      return 2;
    }
    octomap::Pointcloud cloud;
    cloud.reserve(n);
    for (uint32_t i = 0; i < n; ++i) cloud.push_back(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]);
    auto t0 = std::chrono::steady_clock::now();
    octomap::point3d o(origin[0], origin[1], origin[2]);
    tree.insertPointCloud(cloud, o, max_range, false, false);
    auto t1 = std::chrono::steady_clock::now();
    colour(tree, cloud, rgb, o, max_range);
    ms.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
  }
  size_t leafs = 0, occupied = 0;
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
    ++leafs;
    if (tree.isNodeOccupied(*it)) ++occupied;
  }
  finish(tree);
  size_t nodes = tree.size();
  size_t memory = tree.memoryUsage();
  // .ot first: writeBinary turns the tree into maximum likelihood and prunes it.
  tree.write(prefix + ".ot");
  tree.writeBinary(prefix + ".bt");
  std::printf("{\"ms\": [");
  for (size_t i = 0; i < ms.size(); ++i) std::printf("%s%.4f", i ? ", " : "", ms[i]);
  std::printf("], \"leafs\": %zu, \"occupied_leafs\": %zu, \"nodes\": %zu, \"memory_bytes\": %zu}\n", leafs,
              occupied, nodes, memory);
  return 0;
}
