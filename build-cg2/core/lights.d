build-cg2/core/lights.o: core/lights.c core/lights.h core/geometry.h \
 core/scene.h core/image.h core/vec.h core/error.h
core/lights.h:
core/geometry.h:
core/scene.h:
core/image.h:
core/vec.h:
core/error.h:
