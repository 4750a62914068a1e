#pragma once
// Gives what the C library keeps of freed memory back to the system, between the build's big
// stages. glibc keeps freed blocks for reuse; when the next stage's arrays take other sizes,
// the process grows by all it keeps (85 MB of SRTM Gabon's 317 MB after its levels were
// built: trimmed there, its writing peaked at 337 MB instead of 385-390 MB).

#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace terratiles {

inline void returnFreedMemory() {
#if defined(__GLIBC__)
  malloc_trim(0);
#endif
}

}  // namespace terratiles
