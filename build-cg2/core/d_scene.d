build-cg2/core/d_scene.o: core/d_scene.c core/d_scene.h core/bsdf.h \
 core/vec.h core/geometry.h core/scene.h core/image.h core/lights.h \
 core/params.h
core/d_scene.h:
core/bsdf.h:
core/vec.h:
core/geometry.h:
core/scene.h:
core/image.h:
core/lights.h:
core/params.h:
