build-cg2/cli/cmd_render.o: cli/cmd_render.c core/camera.h core/scene.h \
 core/image.h core/vec.h cli/cli.h core/error.h core/image_io.h \
 core/render.h core/integrator.h core/sampler.h core/scene.h
core/camera.h:
core/scene.h:
core/image.h:
core/vec.h:
cli/cli.h:
core/error.h:
core/image_io.h:
core/render.h:
core/integrator.h:
core/sampler.h:
core/scene.h:
