build-cg2/core/gltf_load.o: core/gltf_load.cpp core/error.h \
 core/image_io.h core/image.h core/vec.h core/scene.h
core/error.h:
core/image_io.h:
core/image.h:
core/vec.h:
core/scene.h:
