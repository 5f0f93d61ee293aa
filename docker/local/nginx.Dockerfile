# nginx from Debian's package, for hosts where the nginx image cannot be pulled
# (scripts/docker_smoke.sh). Its only site is the one mounted in /etc/nginx/conf.d/.
ARG BASE_IMAGE=l3-local/debian:bookworm
FROM ${BASE_IMAGE}
RUN apt-get update \
    && apt-get install -y --no-install-recommends nginx \
    && rm -rf /var/lib/apt/lists/* /etc/nginx/sites-enabled/default \
    && ln -sf /dev/stdout /var/log/nginx/access.log \
    && ln -sf /dev/stderr /var/log/nginx/error.log
STOPSIGNAL SIGQUIT
CMD ["nginx", "-g", "daemon off;"]
