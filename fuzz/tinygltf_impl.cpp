/* tinygltf compiled from Debian's header for the fuzz build only, so that its
 * JSON and accessor parsing is instrumented (coverage, ASan) like our own
 * code; `make` and `make test` link the shared libtinygltf instead. The stb
 * image functions it declares come from the shared libstb. */
#define TINYGLTF_IMPLEMENTATION
#include <tiny_gltf.h>
