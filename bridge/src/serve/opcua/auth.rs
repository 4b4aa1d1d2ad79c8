//! Who may do what on the OPC UA face: anonymous clients read and subscribe (where
//! `[opcua] anonymous` allows), users of the users file also call the methods. A
//! password is taken only over a secured endpoint (Basic256Sha256), never over `none`.

use super::login_throttle::LoginThrottle;
use super::users::Users;
use async_trait::async_trait;
use opcua::crypto::SecurityPolicy;
use opcua::server::authenticator::{
    user_pass_security_policy_id, AuthManager, Password, UserToken,
};
use opcua::server::ServerEndpoint;
use opcua::types::{Error, NodeId, StatusCode, UAString, UserTokenPolicy, UserTokenType};
use std::sync::Arc;
use std::time::Instant;

/// The policy id of anonymous tokens (the one the server checks them against).
const POLICY_ID_ANONYMOUS: &str = "anonymous";
/// User tokens of the users file: `user:NAME` (never the anonymous token's id).
const USER_PREFIX: &str = "user:";

/// The method identifiers (their string node ids in the machine's namespace).
pub const START_PROGRAM: &str = "StartProgram";
pub const ABORT: &str = "Abort";
pub const ACKNOWLEDGE: &str = "Acknowledge";

pub struct Auth {
    users: Arc<Users>,
    anonymous: bool,
    may_start: bool,
    throttle: Arc<LoginThrottle>,
}

impl Auth {
    pub fn new(users: Users, anonymous: bool, may_start: bool) -> Self {
        Self {
            users: Arc::new(users),
            anonymous,
            may_start,
            throttle: Arc::default(),
        }
    }

    /// The failed logins' throttle (its summary is also logged periodically).
    pub fn throttle(&self) -> Arc<LoginThrottle> {
        self.throttle.clone()
    }

    /// The user a token is of (`None`: anonymous).
    pub fn user_of(token: &UserToken) -> Option<&str> {
        token.0.strip_prefix(USER_PREFIX)
    }

    /// The last part of a method's id in our namespace (`Machines.M.Production.X` -> X).
    fn method_name(id: &NodeId) -> Option<String> {
        match &id.identifier {
            opcua::types::Identifier::String(s) if id.namespace != 0 => {
                s.as_ref().rsplit('.').next().map(str::to_string)
            }
            _ => None,
        }
    }
}

fn rejected(why: impl Into<String>) -> Error {
    Error::new(StatusCode::BadIdentityTokenRejected, why.into())
}

#[async_trait]
impl AuthManager for Auth {
    async fn authenticate_anonymous_token(&self, _endpoint: &ServerEndpoint) -> Result<(), Error> {
        if self.anonymous {
            Ok(())
        } else {
            Err(rejected(
                "anonymous access is off (opcua.anonymous = false)",
            ))
        }
    }

    async fn authenticate_username_identity_token(
        &self,
        endpoint: &ServerEndpoint,
        username: &str,
        password: &Password,
    ) -> Result<UserToken, Error> {
        if endpoint.security_policy() == SecurityPolicy::None {
            return Err(rejected("no password over an endpoint without security"));
        }
        let account = LoginThrottle::account(username, self.users.contains(username));
        let wait = self.throttle.wait(&account, Instant::now());
        if !wait.is_zero() {
            tokio::time::sleep(wait).await;
        }
        let (users, name, pw) = (
            self.users.clone(),
            username.to_string(),
            password.get().to_string(),
        );
        // argon2id takes tens of milliseconds on purpose: not on the face's runtime.
        let ok = tokio::task::spawn_blocking(move || users.verify(&name, &pw))
            .await
            .unwrap_or(false);
        let now = Instant::now();
        self.throttle.record(&account, ok, now);
        if ok {
            tracing::info!(user = username, "OPC UA face: user logged in");
            Ok(UserToken(format!("{USER_PREFIX}{username}")))
        } else {
            if let Some(line) = self.throttle.summary(now) {
                tracing::warn!("{line}");
            }
            Err(rejected("unknown user or wrong password"))
        }
    }

    fn is_user_executable(&self, token: &UserToken, method_id: &NodeId) -> bool {
        if Self::user_of(token).is_none() {
            return false;
        }
        match Self::method_name(method_id).as_deref() {
            Some(START_PROGRAM) => self.may_start,
            Some(ABORT | ACKNOWLEDGE) => true,
            _ => false,
        }
    }

    fn user_token_policies(&self, endpoint: &ServerEndpoint) -> Vec<UserTokenPolicy> {
        let mut v = Vec::new();
        if self.anonymous {
            v.push(UserTokenPolicy {
                policy_id: UAString::from(POLICY_ID_ANONYMOUS),
                token_type: UserTokenType::Anonymous,
                issued_token_type: UAString::null(),
                issuer_endpoint_url: UAString::null(),
                security_policy_uri: UAString::null(),
            });
        }
        if endpoint.security_policy() != SecurityPolicy::None && !self.users.is_empty() {
            v.push(UserTokenPolicy {
                policy_id: user_pass_security_policy_id(endpoint),
                token_type: UserTokenType::UserName,
                issued_token_type: UAString::null(),
                issuer_endpoint_url: UAString::null(),
                security_policy_uri: UAString::null(),
            });
        }
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use opcua::server::ANONYMOUS_USER_TOKEN_ID;

    fn method(name: &str) -> NodeId {
        NodeId::new(2, format!("Machine.Production.{name}"))
    }

    #[test]
    fn users_call_the_methods_anonymous_clients_none_start_only_with_may_start() {
        let user = UserToken(format!("{USER_PREFIX}mes"));
        let anonymous = UserToken(ANONYMOUS_USER_TOKEN_ID.to_string());
        for may_start in [false, true] {
            let auth = Auth::new(Users::default(), true, may_start);
            assert_eq!(
                auth.is_user_executable(&user, &method(START_PROGRAM)),
                may_start
            );
            for m in [ABORT, ACKNOWLEDGE] {
                assert!(auth.is_user_executable(&user, &method(m)), "{m}");
            }
            for m in [START_PROGRAM, ABORT, ACKNOWLEDGE] {
                assert!(!auth.is_user_executable(&anonymous, &method(m)), "{m}");
            }
            // Only the machine's methods: not a method of namespace 0 of that name.
            let other = NodeId::new(0, format!("Machine.Production.{ABORT}"));
            assert!(!auth.is_user_executable(&user, &other));
        }
    }
}
