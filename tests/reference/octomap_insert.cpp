// Reference for occgp's tests and benchmarks: liboctomap's insertPointCloud called
// directly from C++, with no occgp code in between.
//
//   octomap_insert OUT.ot RES HIT MISS CMIN CMAX MAXRANGE DISCRETIZE SCAN.bin [SCAN.bin ...]
//       Insert the scans in order into one fresh OcTree and write it as a .ot file.
//   octomap_insert --time REPEATS RES MAXRANGE SCAN.bin
//       Print the best wall time in seconds of inserting the scan into a fresh tree.
//   octomap_insert --sequence cloud|rays RES MAXRANGE SCAN.bin [SCAN.bin ...]
//       Insert the scans in order into one tree with insertPointCloud (cloud) or
//       insertPointCloudRays (rays); print each insertion's wall time in seconds.
//
// SCAN.bin holds float32 values: the origin (x y z), then the points (x y z)...
#include <octomap/octomap.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <string>
#include <vector>

static bool read_scan(const char* path, octomap::point3d& origin, octomap::Pointcloud& cloud) {
  std::ifstream g(path, std::ios::binary | std::ios::ate);
  if (!g) return false;
  std::streamsize bytes = g.tellg();
  g.seekg(0);
  std::vector<float> data(bytes / sizeof(float));
  g.read(reinterpret_cast<char*>(data.data()), bytes);
  if (data.size() < 3 || data.size() % 3 != 0) return false;
  origin = octomap::point3d(data[0], data[1], data[2]);
  cloud.reserve(data.size() / 3 - 1);
  for (size_t i = 3; i < data.size(); i += 3) cloud.push_back(data[i], data[i + 1], data[i + 2]);
  return true;
}

int main(int argc, char** argv) {
  if (argc >= 6 && std::string(argv[1]) == "--time") {
    int repeats = std::atoi(argv[2]);
    double res = std::atof(argv[3]), maxrange = std::atof(argv[4]);
    octomap::point3d origin;
    octomap::Pointcloud cloud;
    if (!read_scan(argv[5], origin, cloud)) return 2;
    double best = 1e300;
    for (int r = 0; r < repeats; ++r) {
      octomap::OcTree tree(res);
      auto t0 = std::chrono::steady_clock::now();
      tree.insertPointCloud(cloud, origin, maxrange, false, false);
      auto t1 = std::chrono::steady_clock::now();
      best = std::min(best, std::chrono::duration<double>(t1 - t0).count());
    }
    std::printf("%.9f\n", best);
    return 0;
  }
  if (argc >= 6 && std::string(argv[1]) == "--sequence") {
    bool rays = std::string(argv[2]) == "rays";
    octomap::OcTree tree(std::atof(argv[3]));
    double maxrange = std::atof(argv[4]);
    for (int i = 5; i < argc; ++i) {
      octomap::point3d origin;
      octomap::Pointcloud cloud;
      if (!read_scan(argv[i], origin, cloud)) return 3;
      auto t0 = std::chrono::steady_clock::now();
      if (rays)
        tree.insertPointCloudRays(cloud, origin, maxrange, false);
      else
        tree.insertPointCloud(cloud, origin, maxrange, false, false);
      auto t1 = std::chrono::steady_clock::now();
      std::printf("%.9f\n", std::chrono::duration<double>(t1 - t0).count());
    }
    return 0;
  }
  if (argc < 10) {
    std::fprintf(stderr, "usage: see the comment at the top of octomap_insert.cpp\n");
    return 2;
  }
  octomap::OcTree tree(std::atof(argv[2]));
  tree.setProbHit(std::atof(argv[3]));
  tree.setProbMiss(std::atof(argv[4]));
  tree.setClampingThresMin(std::atof(argv[5]));
  tree.setClampingThresMax(std::atof(argv[6]));
  double maxrange = std::atof(argv[7]);
  bool discretize = std::atoi(argv[8]) != 0;
  for (int i = 9; i < argc; ++i) {
    octomap::point3d origin;
    octomap::Pointcloud cloud;
    if (!read_scan(argv[i], origin, cloud)) return 3;
    tree.insertPointCloud(cloud, origin, maxrange, false, discretize);
  }
  return tree.write(argv[1]) ? 0 : 4;
}
