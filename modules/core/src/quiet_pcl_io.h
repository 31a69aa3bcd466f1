#pragma once
// Private to the core's readers and writers.
#include <exception>
#include <string>

#include <pcl/console/print.h>

namespace paps::detail {

// Runs one of PCL's readers or writers (a call returning PCL's int status) with its console
// silenced (it prints its own complaint; our exception is the one clear line), and turns an
// exception from it into status -1 with its message in `thrown`.
template <typename F>
int quietPclIo(F&& io, std::string& thrown) {
  const auto level = pcl::console::getVerbosityLevel();
  pcl::console::setVerbosityLevel(pcl::console::L_ALWAYS);
  int rc = -1;
  try {
    rc = io();
  } catch (const std::exception& e) {
    thrown = e.what();
    rc = -1;
  }
  pcl::console::setVerbosityLevel(level);
  return rc;
}

}  // namespace paps::detail
