build-cg2/core/scene.o: core/scene.c core/scene.h core/image.h core/vec.h \
 core/accel.h core/error.h core/geometry.h core/lights.h
core/scene.h:
core/image.h:
core/vec.h:
core/accel.h:
core/error.h:
core/geometry.h:
core/lights.h:
