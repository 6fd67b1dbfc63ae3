build-cg2/core/camera.o: core/camera.c core/camera.h core/scene.h \
 core/image.h core/vec.h
core/camera.h:
core/scene.h:
core/image.h:
core/vec.h:
