#include <iostream>

#include "tools/terratiles/run_cli.h"

int main(int argc, char** argv) {
  return terratiles::runCli(std::vector<std::string>(argv, argv + argc), std::cin, std::cout, std::cerr);
}
