build-cg2/core/params.o: core/params.c core/params.h core/scene.h \
 core/image.h core/vec.h core/error.h
core/params.h:
core/scene.h:
core/image.h:
core/vec.h:
core/error.h:
