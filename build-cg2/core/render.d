build-cg2/core/render.o: core/render.c core/render.h core/integrator.h \
 core/sampler.h core/scene.h core/image.h core/vec.h core/camera.h \
 core/error.h core/parallel.h
core/render.h:
core/integrator.h:
core/sampler.h:
core/scene.h:
core/image.h:
core/vec.h:
core/camera.h:
core/error.h:
core/parallel.h:
