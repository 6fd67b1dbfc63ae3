build-cg2/core/accel.o: core/accel.c core/accel.h core/scene.h \
 core/image.h core/vec.h core/error.h
core/accel.h:
core/scene.h:
core/image.h:
core/vec.h:
core/error.h:
