build-cg2/core/geometry.o: core/geometry.c core/geometry.h core/scene.h \
 core/image.h core/vec.h
core/geometry.h:
core/scene.h:
core/image.h:
core/vec.h:
