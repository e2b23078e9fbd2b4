"""``ecs-anim batch``: clips x bodies x grounds on local cores or a Ray cluster, and its HTML
report.

* :mod:`.command`: the ``batch`` command's arguments and the plan they give;
* :mod:`.plan`: bodies, grounds, template, jobs and the checked plan; :mod:`.plan_parts` reads
  its parts from text and files, :mod:`.manifest` from a manifest;
* :mod:`.driver`: :func:`~ecs_anim.apps.batch.driver.run_batch`, which holds the folder
  (:mod:`.folder_lock`), skips jobs done with the same inputs (:mod:`.job_hash`), runs the rest on an engine (:mod:`.local_engine`,
  :mod:`.ray_engine`), writes each job's files whole (:mod:`.job_outputs`), shows
  :mod:`.progress`, and writes :mod:`.metrics_files` and the report (:mod:`.report`);
* :mod:`.jobs`: running one job, as a worker does.
"""
